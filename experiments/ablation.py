"""The training recipe's ablation: each part added in turn, equal training
time, whole test rollouts scored (``experiments.tasks.ablation``).

  python -m experiments.ablation --data=data/small --out=runs/ablation \
      [--minutes=8] [--variants=previous,stride3,...]
"""

from absl import app
from absl import flags

from experiments import runtime
from experiments import tasks

_DATA = flags.DEFINE_string("data", None, "Dataset directory (small config).")
_OUT = flags.DEFINE_string("out", None, "Output directory (one run each).")
_MINUTES = flags.DEFINE_float("minutes", 8.0,
                              "Training wall time per variant (minutes).")
_VARIANTS = flags.DEFINE_list(
    "variants", None, "Variants to run (default: all): "
    + ", ".join(name for name, _ in tasks.ABLATION))
_MAX = flags.DEFINE_integer("max_trajectories", 7,
                            "Test trajectories per variant (7: one per group).",
                            lower_bound=1)
_UNCONSTRAINED = flags.DEFINE_bool(
    "unconstrained", False, "Also roll out without the solid constraint.")


def main(argv):
  del argv
  if _MINUTES.value <= 0:
    raise app.UsageError(f"--minutes={_MINUTES.value}; allowed: > 0")
  known = [name for name, _ in tasks.ABLATION]
  unknown = sorted(set(_VARIANTS.value or ()) - set(known))
  if unknown:
    raise app.UsageError(f"--variants={','.join(_VARIANTS.value)}: unknown "
                         f"{unknown}; allowed: a comma-separated subset of "
                         f"{known}")
  runtime.existing_dir("data", _DATA.value, holding="train.h5")
  runtime.existing_dir("data", _DATA.value, holding="test.h5")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  rows = tasks.ablation(_DATA.value, _OUT.value, minutes=_MINUTES.value,
                        variants=_VARIANTS.value,
                        max_trajectories=_MAX.value,
                        unconstrained=_UNCONSTRAINED.value)
  print(tasks.ablation_table(rows))


if __name__ == "__main__":
  flags.mark_flags_as_required(["data", "out"])
  runtime.run(main)
