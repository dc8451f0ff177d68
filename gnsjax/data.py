"""Reading datasets for training and rollouts (host side, numpy only).

A training example is a *window*: C + 1 consecutive frames of one trajectory
(C = 6 input positions, the last frame the target). ``WindowDataset`` serves
the windows of a split in a seeded random order that is a pure function of
(seed, index), so training resumed at step k reads exactly what an
uninterrupted run would have. It reads per window from HDF5, so datasets
larger than memory work: a window is a few kB and reads in ~0.1 ms.
"""

import os
from typing import Iterator, NamedTuple

import numpy as np

from mpm import io as mpm_io

DEFAULT_INPUT_FRAMES = 6


class NormalizationStats(NamedTuple):
  """Per-frame velocity and acceleration statistics [2] (m/frame, m/frame^2)."""
  vel_mean: np.ndarray
  vel_std: np.ndarray
  acc_mean: np.ndarray
  acc_std: np.ndarray


class Window(NamedTuple):
  """C + 1 frames of one trajectory.

  Attributes:
    positions: float32 [C + 1, N, 2] (m).
    particle_type: int32 [N].
    boundary_positions: float32 [Nb, 2]; boundary_type: int32 [Nb].
    trajectory: index of the trajectory in its file; start: first frame.
  """
  positions: np.ndarray
  particle_type: np.ndarray
  boundary_positions: np.ndarray
  boundary_type: np.ndarray
  trajectory: int
  start: int


def load_stats(path: str) -> NormalizationStats:
  """The normalisation statistics of a dataset file (training split's)."""
  header = mpm_io.read_header(path)
  missing = [k for k in NormalizationStats._fields if k not in header]
  if missing:
    raise mpm_io.FormatError(f"{path}: no normalisation statistics "
                             f"({missing} missing); regenerate the dataset "
                             "or import it with statistics")
  return NormalizationStats(*(np.asarray(header[k], np.float32)
                              for k in NormalizationStats._fields))


class WindowDataset:
  """The windows of one split file, in a seeded shuffled order.

  ``dataset[k]`` is window k of the stream: epoch k // len(dataset) in the
  permutation drawn from (seed, epoch). Not thread-safe (one HDF5 handle).
  """

  def __init__(self, path: str, *, input_frames: int = DEFAULT_INPUT_FRAMES,
               seed: int = 0, shuffle: bool = True):
    self.path = path
    self.window = input_frames + 1
    self.seed = seed
    self.shuffle = shuffle
    self._file = mpm_io.open_file(path)
    self._names = sorted(self._file.keys())
    self._positions = [self._file[n]["positions"] for n in self._names]
    lengths = np.array([p.shape[0] for p in self._positions])
    if np.any(lengths < self.window):
      raise mpm_io.FormatError(
          f"{path}: trajectories need at least {self.window} frames for "
          f"windows of {input_frames} inputs + 1 target; shortest has "
          f"{lengths.min()}")
    counts = lengths - self.window + 1
    self._offsets = np.concatenate([[0], np.cumsum(counts)])
    self._static = {}
    self._epoch, self._order = -1, None

  def __len__(self) -> int:
    """Windows per epoch."""
    return int(self._offsets[-1])

  def close(self):
    self._file.close()

  def __enter__(self):
    return self

  def __exit__(self, *exc):
    self.close()

  def _static_arrays(self, i: int):
    if i not in self._static:
      g = self._file[self._names[i]]
      self._static[i] = (g["particle_type"][()],
                         g["boundary_positions"][()], g["boundary_type"][()])
    return self._static[i]

  def _flat_index(self, k: int) -> int:
    epoch, i = divmod(int(k), len(self))
    if not self.shuffle:
      return i
    if epoch != self._epoch:
      rng = np.random.default_rng([self.seed, epoch])
      self._epoch, self._order = epoch, rng.permutation(len(self))
    return int(self._order[i])

  def __getitem__(self, k: int) -> Window:
    flat = self._flat_index(k)
    t = int(np.searchsorted(self._offsets, flat, side="right") - 1)
    start = flat - int(self._offsets[t])
    positions = self._positions[t][start:start + self.window]
    return Window(positions, *self._static_arrays(t), t, start)

  def iterate(self, start: int = 0) -> Iterator[Window]:
    """Windows k = start, start + 1, ... forever."""
    k = start
    while True:
      yield self[k]
      k += 1


def trajectories(path: str) -> Iterator[mpm_io.Trajectory]:
  """Whole trajectories of a split file (for rollouts and evaluation)."""
  return mpm_io.read_trajectories(path)


def split_path(data_dir: str, split: str) -> str:
  """``<data_dir>/<split>.h5``, with a clear error when it is missing."""
  path = os.path.join(data_dir, f"{split}.h5")
  if not os.path.exists(path):
    present = sorted(f for f in os.listdir(data_dir) if f.endswith(".h5")) \
        if os.path.isdir(data_dir) else []
    raise mpm_io.FormatError(f"{path}: no {split} split; present: {present}")
  return path


__all__ = ["NormalizationStats", "Window", "WindowDataset", "load_stats",
           "split_path", "trajectories"]
