"""The MPM against laboratory granular flows, both rheologies side by side.

  python -m experiments.validation --out=DIR [--aspect_ratios=0.5,1,2,4,8] \
      [--spacing=0.0025] [--incline_angles=32,34,36] [--incline_dx=0.001] \
      [--rheologies=drucker_prager,mu_i]

The study is ``experiments.studies.validation``: the column collapse's
runout and final height against Lube et al. (2005), Lajeunesse et al.
(2005) and Balmforth & Kerswell (2005), and steady flow down a rough
incline against the Bagnold profile. This writes ``validation.md``,
``column.csv``, ``incline.csv``, ``column.png``, ``incline.png`` and
``environment.json`` (machine, load, command).
"""

import sys

from absl import flags

from experiments import runtime
from experiments.studies import validation

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_SETTINGS = runtime.define_flags(validation.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(
      validation.Settings, _SETTINGS,
      command=" ".join(["python -m experiments.validation"] + sys.argv[1:]))
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  summary = validation.run(settings, _OUT.value)
  print(validation.report(summary), end="")


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
