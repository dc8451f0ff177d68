"""Averages the parameters of trained runs into a new run (a model soup).

  python -m experiments.average_runs --workdirs=RUN_A,RUN_B --weights=0.5,0.5 \\
      --out=DIR
  python -m experiments.average_runs --workdirs=RUN@32000,RUN@36000,RUN@40000 \\
      --out=DIR          # one run's kept checkpoints

The runs must share architecture, data and statistics (a model and its
fine-tunings); the result is a run directory like any other (evaluate it,
roll it out, fine-tune from it). See ``gnsjax.averaging``.
"""

from absl import flags

from experiments import runtime
from gnsjax import averaging

_WORKDIRS = flags.DEFINE_list(
    "workdirs", None, "Two or more run directories or shipped models (each "
    "at its latest checkpoint), or DIR@STEP for a kept checkpoint.")
_WEIGHTS = flags.DEFINE_list(
    "weights", None, "One weight per run, >= 0, summing to 1 (default: "
    "equal).")
_OUT = flags.DEFINE_string("out", None, "New run directory to write.")


def main(argv):
  del argv
  if len(_WORKDIRS.value) < 2:
    raise runtime.InputError(
        f"--workdirs={','.join(_WORKDIRS.value)}: {len(_WORKDIRS.value)} "
        "run(s); allowed: two or more run directories")
  for source in _WORKDIRS.value:
    runtime.existing_dir("workdirs", averaging.source_workdir(source),
                         holding="checkpoints")
  runtime.writable("out", _OUT.value)
  n = len(_WORKDIRS.value)
  try:
    weights = ([1.0 / n] * n if _WEIGHTS.value is None else
               [float(w) for w in _WEIGHTS.value])
  except ValueError as e:
    raise runtime.InputError(f"--weights={','.join(_WEIGHTS.value)}: not "
                             "numbers") from e
  run = averaging.write_average(_WORKDIRS.value, weights, _OUT.value)
  print(f"wrote {_OUT.value}: step {run.step}, the mean of "
        f"{n} runs with weights {weights}")


if __name__ == "__main__":
  flags.mark_flags_as_required(["workdirs", "out"])
  runtime.run(main)
