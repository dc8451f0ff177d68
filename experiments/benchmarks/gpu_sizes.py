"""The GPU command's sizes: what each of its roles measures, and how much.

``sizes_for`` picks FULL on an accelerator, REFERENCE on the CPU (the
reference) and QUICK for smoke tests; the parts (``gpu_mpm``, ``gpu_gns``,
``gpu_train``) read their sizes from a ``Sizes``.
"""

import dataclasses


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure, and how much.

  Attributes:
    frames: frames of the paper trajectory (600).
    repeats: timed repeats of each one-at-a-time figure.
    batch_sizes: copies of the paper scene per vmapped call.
    batch_frames: frames each vmapped call runs (the trajectory's on an
      accelerator; fewer on the CPU, extrapolated).
    batch_repeats: timed repeats of each batch.
    chunk_frames: frames per compiled call (``mpm.simulate``'s 50).
    max_batch: run the batch ``batch_size_for`` picks (capped here).
    dataset_batch: dataset scenes per timed batch; dataset_frames: their
      frames (extrapolated to 600).
    spacings: particle spacings (m) of the speed/accuracy study's MPM rows.
    gns_config: config of the timed model (``experiments/configs``).
    gns_steps: learned steps per timed rollout (0: the whole trajectory).
    gns_batch_sizes: copies per vmapped rollout (1: ``rollout.rollout``).
    gns_repeats: timed repeats of each rollout.
    small_frames: frames of the small model's scene (its agreement and
      timing).
    train_config: config of the timed training.
    second_train_config: a second config timed the same way ("" skips):
      the small config, whose recipe searches (docs/gns_log.md) are what an
      accelerator would shorten.
    train_trajectories: training trajectories generated for it, of
      ``train_frames`` frames.
    train_warmup: steps before the timed ones; train_steps: timed steps,
      logged every ``train_log_every``.
  """
  frames: int = 600
  repeats: int = 3
  batch_sizes: tuple[int, ...] = (1, 8, 64, 256)
  batch_frames: int = 600
  batch_repeats: int = 2
  chunk_frames: int = 50
  max_batch: int = 4096
  dataset_batch: int = 64
  dataset_frames: int = 600
  spacings: tuple[float, ...] = (0.02, 0.01, 0.007, 0.005, 0.0035, 0.0025)
  gns_config: str = "paper"
  gns_steps: int = 0
  gns_batch_sizes: tuple[int, ...] = (1, 8, 32)
  gns_repeats: int = 2
  small_frames: int = 600
  train_config: str = "paper"
  second_train_config: str = "small"
  train_trajectories: int = 2
  train_frames: int = 600
  train_warmup: int = 50
  train_steps: int = 200
  train_log_every: int = 25


# On an accelerator: whole trajectories everywhere.
FULL = Sizes()
# This project's CPU (one core, minutes): the same programs, short runs.
REFERENCE = Sizes(batch_frames=5, batch_repeats=2, chunk_frames=5,
                  max_batch=8, dataset_batch=8, dataset_frames=11,
                  gns_steps=5, gns_batch_sizes=(1, 8), gns_repeats=2,
                  train_trajectories=1, train_frames=100, train_warmup=2,
                  train_steps=6, train_log_every=2)
# Tiny sizes that exercise every measurement in seconds (smoke tests).
# Few distinct programs: the paper scene at its own spacing is the study's
# row, the largest batch reuses the x2 program, the test model's scene is
# the small model's (19 frames: 16 to start from, 1 learned step).
QUICK = Sizes(frames=19, repeats=1, batch_sizes=(1, 2), batch_frames=3,
              batch_repeats=1, chunk_frames=2, max_batch=2, dataset_batch=2,
              dataset_frames=3, spacings=(0.005,), gns_config="test",
              gns_steps=2, gns_batch_sizes=(1, 2), gns_repeats=1,
              small_frames=19, train_config="test", second_train_config="test",
              train_trajectories=1,
              train_frames=10, train_warmup=1, train_steps=2,
              train_log_every=1)


def sizes_for(accelerator: bool, quick: bool) -> Sizes:
  """QUICK, else FULL on an accelerator and REFERENCE on the CPU."""
  if quick:
    return QUICK
  return FULL if accelerator else REFERENCE
