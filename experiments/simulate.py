"""Simulates one scene with the MPM and writes its trajectory file.

  python -m experiments.simulate --scene=scene.json --out=traj.h5
  python -m experiments.simulate --seed=7 --out=traj.h5   # a Table 1 scene
  python -m experiments.simulate --seed=7 --front_tolerance=0.1 --out=...
"""

import sys

from absl import app
from absl import flags
from absl import logging
import jax

import mpm
from mpm import budget
from mpm import resolution
from experiments import runtime
from experiments import file_jobs

_SCENE = flags.DEFINE_string("scene", None, "Scene JSON file.")
_SEED = flags.DEFINE_integer(
    "seed", None, "Sample a scene from the paper's Table 1 with this seed "
    "instead of reading --scene.", lower_bound=0)
_OUT = flags.DEFINE_string("out", None, "Output trajectory file (.h5).")
_CHUNK = flags.DEFINE_integer("chunk_frames", 50,
                              "Frames per compiled call (checking interval).",
                              lower_bound=1)
_REST_SPEED = flags.DEFINE_float(
    "rest_speed", None, "Stop stepping once no particle moved faster than "
    "this (m/s) on average over the last 40 frames; the later frames "
    "repeat the last one stepped (default: step every frame).")
_FRONT_TOLERANCE = flags.DEFINE_float(
    "front_tolerance", None, "Instead of the scene's spacing: the largest "
    "front error accepted (a fraction of the runout, e.g. 0.1); the scene "
    "runs at the cheapest spacing the speed/accuracy study measured to "
    "meet it (docs/tradeoff.md), and the choice is printed.")


def main(argv):
  del argv
  if (_SCENE.value is None) == (_SEED.value is None):
    raise app.UsageError("give exactly one of --scene and --seed")
  if _SEED.value is not None:
    scene, seed = mpm.sample_scene(_SEED.value), _SEED.value
  else:
    scene = mpm.Scene.load(runtime.existing_file("scene", _SCENE.value))
    seed = -1
  if _FRONT_TOLERANCE.value is not None:
    chosen = resolution.choose(scene, _FRONT_TOLERANCE.value)
    scene = resolution.at_spacing(scene, chosen.spacing)
    print(f"--front_tolerance={_FRONT_TOLERANCE.value:g}: {chosen.reason}")
  # Before any work: what cannot fit this machine's memory is refused, what
  # takes hours said (with the estimate).
  warning = budget.warning(budget.check_fits(scene,
                                            chunk_frames=_CHUNK.value))
  if warning:
    print(warning, file=sys.stderr)
  if _REST_SPEED.value is not None and not 0 < _REST_SPEED.value < 10:
    raise runtime.InputError(f"--rest_speed={_REST_SPEED.value}: allowed: "
                             "(0, 10) m/s")
  # Before minutes of simulating: the file must be writable at the end.
  runtime.writable("out", _OUT.value, directory=False)
  runtime.enable_compilation_cache()
  logging.info("devices: %s", jax.devices())
  result = file_jobs.simulate_to_file(scene, _OUT.value, seed, _CHUNK.value,
                                      _REST_SPEED.value)
  rested = ("" if result.rest_frame is None else
            f", at rest from frame {result.rest_frame} (later frames repeat "
            "it)")
  print(f"{_OUT.value}: {result.positions.shape[0]} frames, "
        f"{result.positions.shape[1]} particles, {result.n_substeps} "
        f"substeps/frame, {result.wall_time_s:.2f} s simulating "
        f"(+{result.compile_time_s:.2f} s compiling){rested}")


if __name__ == "__main__":
  flags.mark_flag_as_required("out")
  runtime.run(main)
