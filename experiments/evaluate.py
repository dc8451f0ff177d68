"""The paper's evaluation of a trained run: figures, numbers, report.

  python -m experiments.evaluate --workdir=RUN --data=DATA --out=DIR

The study is ``experiments.studies.evaluation``; this writes its files
(``report.md``, ``summary.json``, CSVs and figures) into ``--out``.
"""

from absl import flags

from experiments import runtime
from experiments.studies import evaluation

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_SETTINGS = runtime.define_flags(evaluation.Settings)


def main(argv):
  del argv
  settings = runtime.settings_from_flags(evaluation.Settings, _SETTINGS)
  runtime.existing_dir("workdir", settings.workdir, holding="checkpoints")
  runtime.existing_dir("data", settings.data, holding="test.h5")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  summary = evaluation.run(settings, _OUT.value)
  everything = summary["groups"][0]
  print(f"test MSE {summary['test_mse']:.3e} m^2 (constant velocity "
        f"{summary['test_mse_constant_velocity']:.3e}); front error "
        f"{everything['median_front_error_relative']:.1%} median, "
        f"{everything['max_front_error_relative']:.0%} worst; sand inside "
        f"solids at most {everything['max_inside_solids']:.1%} "
        f"(without the constraint "
        f"{everything.get('free_max_inside_solids', float('nan')):.1%}); "
        f"report: {_OUT.value}/report.md")


if __name__ == "__main__":
  flags.mark_flags_as_required(["workdir", "data", "out"])
  runtime.run(main)
