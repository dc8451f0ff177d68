"""The paper's evaluation of a trained run: figures, numbers, report.

  python -m experiments.evaluate --workdir=RUN --data=DATA --out=DIR
"""

from absl import flags

from experiments import runtime
from experiments import evaluation

_WORKDIR = flags.DEFINE_string("workdir", None, "Training run directory.")
_DATA = flags.DEFINE_string("data", None, "Dataset directory.")
_OUT = flags.DEFINE_string("out", None, "Output directory.")
_MAX = flags.DEFINE_integer("max_trajectories", None,
                            "Evaluate only the first test trajectories.",
                            lower_bound=1)
_REPEATS = flags.DEFINE_integer("timing_repeats", 3,
                                "Repeats of each Table 2 timing (median).",
                                lower_bound=1)
_CHECKPOINTS = flags.DEFINE_bool(
    "checkpoint_errors", True, "Also evaluate the named checkpoints (Fig. 5).")
_UNCONSTRAINED = flags.DEFINE_bool(
    "unconstrained", True, "Also roll out without the solid constraint, to "
    "report how much sand the model alone puts inside solids.")
_CHECKPOINT_TRAJ = flags.DEFINE_integer(
    "checkpoint_trajectories", None,
    "Test trajectories per checkpoint for Fig. 5 (default: all evaluated).",
    lower_bound=1)


def main(argv):
  del argv
  runtime.existing_dir("workdir", _WORKDIR.value, holding="checkpoints")
  runtime.existing_dir("data", _DATA.value, holding="test.h5")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  summary = evaluation.evaluate(
      _WORKDIR.value, _DATA.value, _OUT.value, max_trajectories=_MAX.value,
      timing_repeats=_REPEATS.value, checkpoint_errors=_CHECKPOINTS.value,
      checkpoint_trajectories=_CHECKPOINT_TRAJ.value,
      unconstrained=_UNCONSTRAINED.value)
  everything = summary["groups"][0]
  print(f"test MSE {summary['test_mse']:.3e} m^2 (constant velocity "
        f"{summary['test_mse_constant_velocity']:.3e}); median front error "
        f"{everything['median_front_error_relative']:.1%}; sand inside "
        f"solids at most {everything['max_inside_solids']:.1%} "
        f"(without the constraint "
        f"{everything.get('free_max_inside_solids', float('nan')):.1%}); "
        f"report: {_OUT.value}/report.md")


if __name__ == "__main__":
  flags.mark_flags_as_required(["workdir", "data", "out"])
  runtime.run(main)
