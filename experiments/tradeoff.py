"""The speed/accuracy trade of the MPM and the learned simulator, measured.

  python -m experiments.tradeoff --out=docs/results/tradeoff \
      [--spacings=0.02,0.014,0.01,0.007,0.005,0.0035] \
      [--reference_spacing=0.0025] [--scenes=14] [--repeats=3] \
      [--gns=small=experiments/pretrained/small,...]

The study is ``experiments.studies.tradeoff``; this writes
``tradeoff.json`` (the table ``gnsjax.tradeoff`` reads), ``points.csv``,
``rows.csv``, ``tradeoff.png`` (error against time, log-log, Pareto front
marked), ``tradeoff_batched.png`` and ``tradeoff.md``.
"""

import sys

from absl import flags
from absl import logging

from experiments import runtime
from experiments.studies import tradeoff

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_SETTINGS = runtime.define_flags(tradeoff.Settings)


def main(argv):
  del argv
  logging.set_verbosity(logging.WARNING)  # orbax's restore chatter
  settings = runtime.settings_from_flags(
      tradeoff.Settings, _SETTINGS,
      command=" ".join(["python -m experiments.tradeoff"] + sys.argv[1:]))
  for _, workdir in settings.gns_workdirs():
    runtime.existing_dir("gns", workdir, holding="checkpoints")
  runtime.writable("out", _OUT.value)
  # No persistent compilation cache: the compile times are part of the
  # figures, and a cached program would report its loading time.
  summary = tradeoff.run(settings, _OUT.value)
  print(tradeoff.report(summary))


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
