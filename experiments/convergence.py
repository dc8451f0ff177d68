"""The MPM's answer against its resolution: granular column collapse and the
paper's scenes.

  python -m experiments.convergence --out=DIR [--aspect_ratios=0.5,1,2,4] \
      [--spacings=0.01,0.005,0.0025,0.00125] [--cfl=0.4] \
      [--paper_scenes=0,3] [--paper_spacings=0.01,0.005,0.0025]

The study is ``experiments.studies.convergence``; this writes
``convergence.csv``, ``convergence_paper.csv``, ``convergence.md``,
``deposits.png`` (the final deposits at every spacing, overlaid) and
``environment.json`` (machine, load, command).
"""

import sys

from absl import flags

from experiments import runtime
from experiments.studies import convergence

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_SETTINGS = runtime.define_flags(convergence.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(
      convergence.Settings, _SETTINGS,
      command=" ".join(["python -m experiments.convergence"] + sys.argv[1:]))
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  summary = convergence.run(settings, _OUT.value)
  print(convergence.report(summary), end="")


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
