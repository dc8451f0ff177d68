"""Plain against smoothed gradients over a whole avalanche.

  python -m experiments.gradient_check --out=docs/results/gradient_check \\
      [--sigma=0.05 --num_samples=16 --xs=0.6,0.8,1.0,1.2] \\
      [--objective=passed_fraction --x_protect=0.4] \\
      [--simulator=gns --workdir=experiments/pretrained/small --hs=0.01,0.001]

On the inverse-design study's scene (the small config's heap, 250 particles,
a semicircle of radius 0.04 m, 600 frames), at each obstacle x: the slope of
the objective over x +- sigma (two runs) and central differences at each of
--hs against jax.grad at x and the smoothed gradients
(``gnsjax.design.smoothing``), through the MPM or a trained learned
simulator. The study is ``experiments.studies.gradient_check``; this writes
``rows.csv``, ``summary.json`` and ``report.md`` (docs/inverse_design.md)
and prints the report.
"""

import os

from absl import flags

from experiments import runtime
from experiments.studies import gradient_check

_OUT = flags.DEFINE_string("out", "out/gradient_check", "Output directory.")
_SETTINGS = runtime.define_flags(gradient_check.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(gradient_check.Settings, _SETTINGS)
  if settings.simulator == "gns":
    runtime.existing_dir("workdir", settings.workdir, holding="checkpoints")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  gradient_check.run(settings, _OUT.value)
  with open(os.path.join(_OUT.value, "report.md")) as f:
    print(f.read())


if __name__ == "__main__":
  runtime.run(main)
