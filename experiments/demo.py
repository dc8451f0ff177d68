"""The end-to-end demo on a small default (``make demo``).

Until the learned simulator lands, the demo simulates the paper's Figure 2
scene (900 particles, a semicircular obstacle) with the MPM, writes the
trajectory file, an animation and a grid of frames, and prints where they are.
"""

from absl import app
from absl import flags

from experiments import runtime
from experiments import tasks

_OUT = flags.DEFINE_string("out", "out/demo", "Output directory.")
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames to simulate.")


def main(argv):
  del argv
  runtime.enable_compilation_cache()
  for name, path in tasks.demo(_OUT.value, _FRAMES.value).items():
    print(f"{name:>10}: {path}")


if __name__ == "__main__":
  app.run(main)
