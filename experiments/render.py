"""Renders a trajectory file: an animation and a PNG grid of frames.

  python -m experiments.render --traj=traj.h5 --out=DIR [--index=0]
  python -m experiments.render --traj=ROLL/truth.h5 \
      --compare=ROLL/predicted.h5 --out=DIR    # MPM and GNS side by side
"""

import shutil

from absl import flags

from experiments import runtime
from experiments import file_jobs

_TRAJ = flags.DEFINE_string("traj", None, "Trajectory file (.h5).")
_OUT = flags.DEFINE_string("out", None, "Output directory.")
_INDEX = flags.DEFINE_integer("index", 0, "Which trajectory of the file.",
                              lower_bound=0)
_FRAMES = flags.DEFINE_list(
    "frames", None, "Frames of the PNG grid (default: six from the first "
    "to the last, so the deposit is in the grid).")
_FORMAT = flags.DEFINE_enum("format", "gif", ["gif", "mp4"],
                            "Animation format (mp4 needs ffmpeg).")
_COMPARE = flags.DEFINE_string(
    "compare", None, "A second trajectory file (e.g. GNS predictions) drawn "
    "beside --traj; each panel is titled by its file's name.")

def _check_frames(value: list[str] | None) -> bool:
  if value is not None and not (value and all(f.isdigit() for f in value)):
    raise flags.ValidationError("expected comma-separated frame indices "
                                "(integers >= 0)")
  return True


flags.register_validator("frames", _check_frames)


def main(argv):
  del argv
  runtime.existing_file("traj", _TRAJ.value)
  runtime.existing_file("compare", _COMPARE.value)
  if _FORMAT.value == "mp4" and shutil.which("ffmpeg") is None:
    raise runtime.InputError("--format=mp4 needs ffmpeg on PATH, which this "
                             "machine lacks; allowed: --format=gif, or "
                             "install ffmpeg")
  runtime.writable("out", _OUT.value)
  frames = None if _FRAMES.value is None else [int(f) for f in _FRAMES.value]
  for path in file_jobs.render_file(_TRAJ.value, _OUT.value, _INDEX.value,
                                    frames, _FORMAT.value,
                                    compare_path=_COMPARE.value):
    print(path)


if __name__ == "__main__":
  flags.mark_flags_as_required(["traj", "out"])
  runtime.run(main)
