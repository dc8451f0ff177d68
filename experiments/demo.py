"""The end-to-end demo on a small default (``make demo``).

Builds a small dataset with the MPM, fine-tunes the shipped small pretrained
model on it (or trains briefly from scratch), rolls it out on an unseen test
scene (a triangle obstacle, never seen in training), writes the metrics and
an MPM | GNS animation, and prints where everything is. The study is
``experiments.studies.demo``.
"""

from absl import flags
from absl import logging

from experiments import runtime
from experiments.studies import demo

_OUT = flags.DEFINE_string("out", "out/demo", "Output directory.")
_SETTINGS = runtime.define_flags(demo.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(demo.Settings, _SETTINGS)
  runtime.writable("out", _OUT.value)
  # Orbax and XLA log every checkpoint and compilation at INFO: not for the
  # demo's reader (progress bars and the final figures are).
  logging.set_verbosity(logging.WARNING)
  runtime.enable_compilation_cache()
  summary = demo.run(settings, _OUT.value)
  for key, value in summary["metrics"].items():
    print(f"{key:>32}: {value:.4g}" if isinstance(value, float) else
          f"{key:>32}: {value}")
  for name, path in summary["paths"].items():
    print(f"{name:>10}: {path}")


if __name__ == "__main__":
  runtime.run(main)
