"""The paper's evaluation of a trained run: figures, numbers, report.

  python -m experiments.evaluate --workdir=RUN --data=DATA --out=DIR
"""

import os

from absl import app
from absl import flags

from experiments import runtime
from gnsjax import evaluate
from mpm import io as mpm_io

_WORKDIR = flags.DEFINE_string("workdir", None, "Training run directory.")
_DATA = flags.DEFINE_string("data", None, "Dataset directory.")
_OUT = flags.DEFINE_string("out", None, "Output directory.")
_MAX = flags.DEFINE_integer("max_trajectories", None,
                            "Evaluate only the first test trajectories.")
_REPEATS = flags.DEFINE_integer("timing_repeats", 3,
                                "Repeats of each Table 2 timing (median).")
_CHECKPOINTS = flags.DEFINE_bool(
    "checkpoint_errors", True, "Also evaluate the named checkpoints (Fig. 5).")
_BASELINE = flags.DEFINE_bool(
    "baseline", False, "Only compare the model with a constant-velocity "
    "baseline (one-step loss and 50-step rollouts on the test split).")
_CHECKPOINT_TRAJ = flags.DEFINE_integer(
    "checkpoint_trajectories", None,
    "Test trajectories per checkpoint for Fig. 5 (default: all evaluated).")


def main(argv):
  del argv
  runtime.enable_compilation_cache()
  if _BASELINE.value:
    result = evaluate.constant_velocity_comparison(_WORKDIR.value, _DATA.value)
    os.makedirs(_OUT.value, exist_ok=True)
    mpm_io.write_json(os.path.join(_OUT.value, "baseline.json"), result)
    for k, v in result.items():
      if not isinstance(v, list):
        print(f"{k}: {v:.6g}" if isinstance(v, float) else f"{k}: {v}")
    return
  summary = evaluate.evaluate(_WORKDIR.value, _DATA.value, _OUT.value,
                              max_trajectories=_MAX.value,
                              timing_repeats=_REPEATS.value,
                              checkpoint_errors=_CHECKPOINTS.value,
                              checkpoint_trajectories=_CHECKPOINT_TRAJ.value)
  print(f"test MSE {summary['test_mse']:.3e} m^2; report: "
        f"{_OUT.value}/report.md")


if __name__ == "__main__":
  flags.mark_flags_as_required(["workdir", "data", "out"])
  app.run(main)
