"""The end-to-end demo on a small default (``make demo``).

Builds a small dataset with the MPM, fine-tunes the shipped small pretrained
model on it (or trains briefly from scratch), rolls it out on an unseen test
scene (a triangle obstacle, never seen in training), writes the metrics and
an MPM | GNS animation, and prints where everything is.
"""

from absl import flags
from absl import logging

from experiments import runtime
from experiments import tasks
from experiments.configs import small

# The small model's first prediction needs its input frames at its stride.
_MIN_FRAMES = (small.get_config().train.input_frames *
               small.get_config().train.frame_stride + 1)

_OUT = flags.DEFINE_string("out", "out/demo", "Output directory.")
_STEPS = flags.DEFINE_integer("finetune_steps", 200, "Training steps.",
                              lower_bound=1)
_TRAIN = flags.DEFINE_integer("num_train", 4, "Training scenes to simulate.",
                              lower_bound=1)
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames per scene.",
                               lower_bound=_MIN_FRAMES)
_PRETRAINED = flags.DEFINE_bool("pretrained", True,
                                "Start from the shipped small model.")


def main(argv):
  del argv
  runtime.writable("out", _OUT.value)
  # Orbax and XLA log every checkpoint and compilation at INFO: not for the
  # demo's reader (progress bars and the final figures are).
  logging.set_verbosity(logging.WARNING)
  runtime.enable_compilation_cache()
  paths = tasks.demo(_OUT.value, num_train=_TRAIN.value,
                     num_frames=_FRAMES.value,
                     finetune_steps=_STEPS.value,
                     pretrained=tasks.PRETRAINED if _PRETRAINED.value else None)
  for name, path in paths.items():
    print(f"{name:>10}: {path}")


if __name__ == "__main__":
  runtime.run(main)
