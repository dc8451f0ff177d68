"""The training recipe's ablation: each part added in turn, equal training
time, whole test rollouts scored (``experiments.studies.ablation``).

  python -m experiments.ablation --data=data/small --out=runs/ablation \
      [--minutes=8] [--variants=previous,stride3,...]

Writes ``ablation.json`` and ``ablation.md`` into ``--out`` (one run each
beside them) and prints the table.
"""

from absl import flags

from experiments import runtime
from experiments.studies import ablation

_OUT = flags.DEFINE_string("out", None, "Output directory (one run each).")
_SETTINGS = runtime.define_flags(ablation.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(ablation.Settings, _SETTINGS)
  runtime.existing_dir("data", settings.data, holding="train.h5")
  runtime.existing_dir("data", settings.data, holding="test.h5")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  print(ablation.report(ablation.run(settings, _OUT.value)))


if __name__ == "__main__":
  flags.mark_flags_as_required(["data", "out"])
  runtime.run(main)
