"""Where to put an obstacle: projected Adam on gradients through GNS or MPM.

  python -m experiments.inverse_design --out=out/design \\
      [--simulator=gns|mpm] [--objective=passed_fraction --x_protect=0.4] \\
      [--shape=semicircle --size=0.04 --x0=1.0] [--scene=scene.json]

Optimises the obstacle's x in [0.5, 1.3] m, logs the objective per
iteration, re-simulates the start and the optimum with the MPM, runs the
brute-force MPM sweep over x for comparison, and plots the objective against
x for GNS and MPM with the optimiser's path (see docs/inverse_design.md).
"""

from absl import app
from absl import flags

import mpm
from experiments import runtime
from experiments import tasks
from mpm import sampler
from mpm import scene as scene_lib

_OUT = flags.DEFINE_string("out", "out/design", "Output directory.")
_SIMULATOR = flags.DEFINE_enum("simulator", "gns", ["gns", "mpm"],
                               "Whose gradients drive the optimiser.")
_OBJECTIVE = flags.DEFINE_enum(
    "objective", "passed_fraction", ["runout", "passed_fraction", "centroid"],
    "What to minimise.")
_X_PROTECT = flags.DEFINE_float("x_protect", 0.4,
                                "passed_fraction: the protected line (m).")
_TARGET_X = flags.DEFINE_float("target_x", 0.6,
                               "centroid: the target deposit centroid x (m).")
_TEMPERATURE = flags.DEFINE_float(
    "temperature", None, "Temperature (m) of the smooth surrogate.")
_SCENE = flags.DEFINE_string(
    "scene", None, "Scene JSON whose first obstacle is designed (default: "
    "the small config's heap of 250 particles with --shape at --x0).")
_SHAPE = flags.DEFINE_enum("shape", "semicircle",
                           ["semicircle", "rectangle", "triangle"],
                           "Obstacle shape (without --scene).")
_SIZE = flags.DEFINE_list("size", ["0.04"],
                          "Obstacle size (m): radius, or width/base,height.")
# The design range of x (gnsjax.design.placement.X_RANGE, whose import
# would cost seconds before the flags are even checked).
_X_RANGE = sampler.OBSTACLE_X_RANGE
_X0 = flags.DEFINE_float("x0", 1.0, "Starting obstacle x (m), in [%g, %g]."
                         % _X_RANGE)
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames per rollout.",
                               lower_bound=2)
_WORKDIR = flags.DEFINE_string("workdir", tasks.PRETRAINED,
                               "Trained GNS (default: the shipped model); "
                               "empty: MPM only.")
_STEPS = flags.DEFINE_integer("steps", 8, "Gradient evaluations.",
                              lower_bound=1)
_LR = flags.DEFINE_float("learning_rate", 0.05, "Adam step size (m).",
                         lower_bound=0)
_SWEEP = flags.DEFINE_integer("sweep_points", 9, "MPM sweep placements.",
                              lower_bound=2)
_OPTIMISE_SIZE = flags.DEFINE_bool(
    "optimise_size", False, "Optimise the obstacle's size too (Table 1 "
    "ranges).")


_METHOD = flags.DEFINE_enum(
    "method", "adam", ["adam", "adam_smoothed"],
    "adam: plain gradients; adam_smoothed: gradients of the objective "
    "smoothed at --sigma (MPM only; docs/inverse_design.md).")
_SIGMA = flags.DEFINE_float("sigma", 0.05, "Smoothing scale (m) of "
                            "adam_smoothed.", lower_bound=1e-6)
_SAMPLES = flags.DEFINE_integer(
    "num_samples", 16, "Perturbed designs per smoothed gradient (even).",
    lower_bound=2)
_ESTIMATOR = flags.DEFINE_enum("estimator", "score", ["score", "pathwise"],
                               "Estimator of the smoothed gradient.")


def _check_inputs() -> None:
  """Refuses bad flags before anything is created or compiled: the design
  range of x is one range, whether x comes from --x0 or --scene."""
  lo, hi = _X_RANGE
  if _SCENE.value is not None:
    scene = mpm.Scene.load(runtime.existing_file("scene", _SCENE.value))
    if not scene.obstacles:
      raise runtime.InputError(f"--scene={_SCENE.value}: no obstacle to "
                               "design; allowed: a scene with obstacles")
    x = scene.obstacles[0].x
    if not lo <= x <= hi:
      raise runtime.InputError(f"--scene={_SCENE.value}: obstacles[0].x = "
                               f"{x:g}; allowed: [{lo:g}, {hi:g}] m")
  else:
    if not lo <= _X0.value <= hi:
      raise runtime.InputError(f"--x0={_X0.value:g}; allowed: [{lo:g}, "
                               f"{hi:g}] m")
    keys = scene_lib.OBSTACLE_SHAPES[_SHAPE.value]
    ranges = sampler.SIZE_RANGES[_SHAPE.value]
    try:
      size = [float(s) for s in _SIZE.value]
    except ValueError:
      size = []
    # Optimised sizes stay in Table 1's ranges; a fixed one need only fit.
    if _OPTIMISE_SIZE.value:
      ok = all(ranges[k][0] <= s <= ranges[k][1] for k, s in zip(keys, size))
      allowed = ", ".join(f"{k} in [{ranges[k][0]:g}, {ranges[k][1]:g}]"
                          for k in keys) + " m (--optimise_size)"
    else:
      ok = all(s > 0 for s in size)
      allowed = "positive lengths in m"
    if len(size) != len(keys) or not ok:
      raise runtime.InputError(
          f"--size={','.join(_SIZE.value)}: a {_SHAPE.value} needs "
          f"{list(keys)}; allowed: {allowed}")
  if _TEMPERATURE.value is not None and not _TEMPERATURE.value > 0:
    raise runtime.InputError(f"--temperature={_TEMPERATURE.value:g}; "
                             "allowed: > 0 (m)")
  if _METHOD.value == "adam_smoothed":
    if _SIMULATOR.value != "mpm":
      raise runtime.InputError("--method=adam_smoothed runs on the MPM; "
                               "allowed: --simulator=mpm")
    if _SAMPLES.value % 2:
      raise runtime.InputError(f"--num_samples={_SAMPLES.value}; allowed: "
                               "an even number >= 2 (antithetic pairs)")
  if _WORKDIR.value:
    runtime.existing_dir("workdir", _WORKDIR.value, holding="checkpoints")
  elif _SIMULATOR.value == "gns":
    raise app.UsageError("--simulator=gns needs --workdir (a trained "
                         "model); or use --simulator=mpm")
  runtime.writable("out", _OUT.value)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  _check_inputs()
  runtime.enable_compilation_cache()
  summary = tasks.inverse_design(
      _OUT.value, scene_path=_SCENE.value, shape=_SHAPE.value,
      size=[float(s) for s in _SIZE.value], x0=_X0.value,
      num_frames=_FRAMES.value, simulator=_SIMULATOR.value,
      objective=_OBJECTIVE.value, x_protect=_X_PROTECT.value,
      target_x=_TARGET_X.value, temperature=_TEMPERATURE.value,
      workdir=_WORKDIR.value, steps=_STEPS.value,
      learning_rate=_LR.value, sweep_points=_SWEEP.value,
      optimise_size=_OPTIMISE_SIZE.value, method=_METHOD.value,
      sigma=_SIGMA.value, num_samples=_SAMPLES.value,
      estimator=_ESTIMATOR.value)
  print(f"improved under the MPM: {summary['improved_under_mpm']}; "
        f"report: {_OUT.value}/report.md")


if __name__ == "__main__":
  runtime.run(main)
