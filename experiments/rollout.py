"""Rolls a trained model out on a split; writes predicted and true files.

  python -m experiments.rollout --workdir=RUN --data=DATA --out=DIR \
      [--split=test] [--max_trajectories=3]

Writes ``DIR/predicted.h5`` and ``DIR/truth.h5`` (trajectory files with the
same groups; frames before the model's first prediction are the true inputs).
Both hold every ``frame_stride``-th stored frame (the model's learned step),
their scenes' ``frame_dt`` set to match. ``--noproject`` switches the solid
constraint off (to see what the model alone does).
"""

from absl import flags

from experiments import runtime
from experiments import file_jobs

_WORKDIR = flags.DEFINE_string("workdir", None, "Training run directory.")
_DATA = flags.DEFINE_string("data", None, "Dataset directory.")
_OUT = flags.DEFINE_string("out", None, "Output directory.")
_SPLIT = flags.DEFINE_string("split", "test", "Which split to roll out.")
_MAX = flags.DEFINE_integer("max_trajectories", None, "First N only.",
                            lower_bound=1)
_PROJECT = flags.DEFINE_bool("project", True, "Keep sand out of solids after "
                             "every learned step.")


def main(argv):
  del argv
  runtime.existing_dir("workdir", _WORKDIR.value, holding="checkpoints")
  runtime.existing_dir("data", _DATA.value, holding=f"{_SPLIT.value}.h5")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  paths = file_jobs.rollout_to_files(_WORKDIR.value, _DATA.value,
                                     _OUT.value, _SPLIT.value, _MAX.value,
                                     project=_PROJECT.value)
  for name, path in paths.items():
    print(f"{name}: {path}")


if __name__ == "__main__":
  flags.mark_flags_as_required(["workdir", "data", "out"])
  runtime.run(main)
