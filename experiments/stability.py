"""Where each simulator stays finite and physical, and where it breaks.

  python -m experiments.stability --out=docs/results/stability \
      [--workdir=experiments/pretrained/small] [--only=NAME,...]

The study is ``experiments.studies.stability``; this writes its table
(``stability.csv``, ``stability.md``) and one picture per case.
"""

from absl import flags

from experiments import runtime
from experiments.studies import stability

_OUT = flags.DEFINE_string("out", None, "Output directory for the table.")
_SETTINGS = runtime.define_flags(stability.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(stability.Settings, _SETTINGS)
  if settings.workdir:
    runtime.existing_dir("workdir", settings.workdir, holding="checkpoints")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  summary = stability.run(settings, _OUT.value)
  print(f"{len(summary['rows'])} cases, {len(summary['broken'])} not ok: "
        f"{summary['broken']}; table: {_OUT.value}/stability.md")


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
