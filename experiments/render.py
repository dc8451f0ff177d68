"""Renders a trajectory file: an animation and a PNG grid of frames.

  python -m experiments.render --traj=traj.h5 --out=DIR [--index=0]
  python -m experiments.render --traj=ROLL/truth.h5       --compare=ROLL/predicted.h5 --out=DIR      # MPM and GNS side by side
"""

from absl import app
from absl import flags

from experiments import tasks

_TRAJ = flags.DEFINE_string("traj", None, "Trajectory file (.h5).")
_OUT = flags.DEFINE_string("out", None, "Output directory.")
_INDEX = flags.DEFINE_integer("index", 0, "Which trajectory of the file.")
_FRAMES = flags.DEFINE_list("frames", ["1", "80", "120", "180"],
                            "Frames of the PNG grid (the paper's Figure 2).")
_FORMAT = flags.DEFINE_enum("format", "gif", ["gif", "mp4"],
                            "Animation format (mp4 needs ffmpeg).")
_COMPARE = flags.DEFINE_string(
    "compare", None, "A second trajectory file (e.g. GNS predictions) drawn "
    "beside --traj.")


def main(argv):
  del argv
  for path in tasks.render_file(_TRAJ.value, _OUT.value, _INDEX.value,
                                [int(f) for f in _FRAMES.value],
                                _FORMAT.value, compare_path=_COMPARE.value):
    print(path)


if __name__ == "__main__":
  flags.mark_flags_as_required(["traj", "out"])
  app.run(main)
