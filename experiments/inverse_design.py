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

from experiments import runtime
from experiments import tasks

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
_X0 = flags.DEFINE_float("x0", 1.0, "Starting obstacle x (m).")
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames per rollout.")
_WORKDIR = flags.DEFINE_string("workdir", tasks.PRETRAINED,
                               "Trained GNS (default: the shipped model); "
                               "empty: MPM only.")
_STEPS = flags.DEFINE_integer("steps", 8, "Gradient evaluations.")
_LR = flags.DEFINE_float("learning_rate", 0.05, "Adam step size (m).")
_SWEEP = flags.DEFINE_integer("sweep_points", 9, "MPM sweep placements.")
_OPTIMISE_SIZE = flags.DEFINE_bool(
    "optimise_size", False, "Optimise the obstacle's size too (Table 1 "
    "ranges).")


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  runtime.enable_compilation_cache()
  summary = tasks.inverse_design(
      _OUT.value, scene_path=_SCENE.value, shape=_SHAPE.value,
      size=[float(s) for s in _SIZE.value], x0=_X0.value,
      num_frames=_FRAMES.value, simulator=_SIMULATOR.value,
      objective=_OBJECTIVE.value, x_protect=_X_PROTECT.value,
      target_x=_TARGET_X.value, temperature=_TEMPERATURE.value,
      workdir=_WORKDIR.value, steps=_STEPS.value,
      learning_rate=_LR.value, sweep_points=_SWEEP.value,
      optimise_size=_OPTIMISE_SIZE.value)
  print(f"improved under the MPM: {summary['improved_under_mpm']}; "
        f"report: {_OUT.value}/report.md")


if __name__ == "__main__":
  app.run(main)
