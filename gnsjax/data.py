"""Reading datasets for training and rollouts (host side, numpy).

A training example is a *window*: C + 1 frames of one trajectory, ``k =
frame_stride`` stored frames apart (C = 6 input positions, the last frame the
target; one learned step spans k frames). ``WindowDataset`` serves the
windows of a split in a seeded random order that is a pure function of
(seed, index), so training resumed at step k reads exactly what an
uninterrupted run would have; optionally it draws windows with more weight
on moving sand (``motion_weighting``). It reads per window from HDF5, so
datasets larger than memory work: a window is a few kB and reads in ~0.1 ms.
"""

import functools
import os
from typing import Iterator, NamedTuple

import numpy as np

from gnsjax.features import Stats
from mpm import geometry
from mpm import io as mpm_io
from mpm import scene as scene_lib

DEFAULT_INPUT_FRAMES = 6


class Window(NamedTuple):
  """C + 1 frames of one trajectory, ``frame_stride`` apart.

  Attributes:
    positions: float32 [C + 1, N, 2] (m).
    particle_type: int32 [N].
    boundary_positions: float32 [Nb, 2]; boundary_type: int32 [Nb].
    trajectory: index of the trajectory in its file; start: first frame.
    scene: the trajectory's scene (its solids give the SDF features).
  """
  positions: np.ndarray
  particle_type: np.ndarray
  boundary_positions: np.ndarray
  boundary_type: np.ndarray
  trajectory: int
  start: int
  scene: scene_lib.Scene


def load_stats(path: str, stride: int = 1) -> Stats:
  """Normalisation statistics of a dataset file (the training split's).

  Stride 1: the file's stored statistics. Stride k > 1: computed from the
  file's trajectories at that stride (``mpm.io.finite_difference_stats``).
  """
  if int(stride) != stride or stride < 1:
    raise ValueError(f"stride = {stride}; allowed: an integer >= 1")
  if stride > 1:
    stats = mpm_io.finite_difference_stats(
        (t.positions for t in mpm_io.read_trajectories(path)), int(stride))
    return Stats(*(np.asarray(stats[k], np.float32) for k in Stats._fields))
  header = mpm_io.read_header(path)
  missing = [k for k in Stats._fields if k not in header]
  if missing:
    raise mpm_io.FormatError(f"{path}: no normalisation statistics "
                             f"({missing} missing); regenerate the dataset "
                             "or import it with statistics")
  return Stats(*(np.asarray(header[k], np.float32) for k in Stats._fields))


class WindowDataset:
  """The windows of one split file, in a seeded shuffled order.

  ``dataset[k]`` is window k of the stream: epoch k // len(dataset) in the
  order drawn from (seed, epoch). Uniform: a permutation of all windows.
  With ``motion_weighting`` p > 0, windows are drawn (with replacement) with
  probability proportional to (1 - p) + p m / mean(m), where m is the mean
  particle speed over the window: p = 0 is uniform, p = 1 proportional to
  motion, so resting heaps are seen less. Not thread-safe (one HDF5 handle).
  """

  def __init__(self, path: str, *, input_frames: int = DEFAULT_INPUT_FRAMES,
               seed: int = 0, shuffle: bool = True, frame_stride: int = 1,
               motion_weighting: float = 0.0):
    if int(frame_stride) != frame_stride or frame_stride < 1:
      raise ValueError(f"frame_stride = {frame_stride}; allowed: an integer "
                       ">= 1")
    if not 0.0 <= motion_weighting <= 1.0:
      raise ValueError(f"motion_weighting = {motion_weighting}; allowed: "
                       "0 <= p <= 1")
    self.path = path
    self.stride = int(frame_stride)
    self.span = input_frames * self.stride + 1   # stored frames per window
    self.seed = seed
    self.shuffle = shuffle
    self._file = mpm_io.open_file(path)
    self._names = sorted(self._file.keys())
    self._positions = [self._file[n]["positions"] for n in self._names]
    lengths = np.array([p.shape[0] for p in self._positions])
    if np.any(lengths < self.span):
      raise mpm_io.FormatError(
          f"{path}: trajectories need at least {self.span} frames for "
          f"windows of {input_frames} inputs + 1 target at stride "
          f"{self.stride}; shortest has {lengths.min()}")
    counts = lengths - self.span + 1
    self._offsets = np.concatenate([[0], np.cumsum(counts)])
    self._static, self._scenes = {}, {}
    self._epoch, self._order = -1, None
    self._probability = None
    if motion_weighting > 0:
      m = self._window_motion()
      w = (1 - motion_weighting) + motion_weighting * m / max(m.mean(), 1e-30)
      self._probability = w / w.sum()

  def _window_motion(self) -> np.ndarray:
    """Mean particle speed [windows] (m/frame) over each window's span."""
    out = []
    for p in self._positions:
      x = p[()]
      speed = np.mean(np.linalg.norm(np.diff(x, axis=0), axis=-1), -1)
      cum = np.concatenate([[0.0], np.cumsum(speed)])
      n = len(x) - self.span + 1
      span = self.span - 1
      out.append((cum[span:span + n] - cum[:n]) / span)
    return np.concatenate(out)

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

  def _scene(self, i: int) -> scene_lib.Scene:
    if i not in self._scenes:
      self._scenes[i] = scene_lib.Scene.from_json(
          self._file[self._names[i]].attrs["scene"])
    return self._scenes[i]

  def _flat_index(self, k: int) -> int:
    epoch, i = divmod(int(k), len(self))
    if not self.shuffle:
      return i
    if epoch != self._epoch:
      rng = np.random.default_rng([self.seed, epoch])
      if self._probability is None:
        order = rng.permutation(len(self))
      else:
        order = rng.choice(len(self), size=len(self), p=self._probability)
      self._epoch, self._order = epoch, order
    return int(self._order[i])

  def locate(self, k: int) -> tuple[int, int]:
    """(trajectory, first stored frame) of window k of the stream, without
    reading it."""
    flat = self._flat_index(k)
    t = int(np.searchsorted(self._offsets, flat, side="right") - 1)
    return t, flat - int(self._offsets[t])

  def __getitem__(self, k: int) -> Window:
    t, start = self.locate(k)
    positions = self._positions[t][start:start + self.span:self.stride]
    return Window(positions, *self._static_arrays(t), t, start, self._scene(t))

  def iterate(self, start: int = 0) -> Iterator[Window]:
    """Windows k = start, start + 1, ... forever."""
    k = start
    while True:
      yield self[k]
      k += 1


@functools.lru_cache(maxsize=256)
def _solids_of_json(scene_json: str, spacing: float) -> geometry.SDFGrid:
  grid = geometry.scene_sdf_grid(scene_lib.Scene.from_json(scene_json),
                                 spacing)
  return grid.replace(values=np.asarray(grid.values))


def solids_of(scene, spacing: float) -> geometry.SDFGrid:
  """The SDF grid of an ``mpm.Scene`` (numpy values; cached per scene)."""
  return _solids_of_json(scene.to_json(), float(spacing))


def trajectories(path: str) -> Iterator[mpm_io.Trajectory]:
  """Whole trajectories of a split file (for rollouts and evaluation)."""
  return mpm_io.read_trajectories(path)


def num_trajectories(path: str) -> int:
  """How many trajectories a split file holds."""
  with mpm_io.open_file(path) as f:
    return len(f.keys())


def split_path(data_dir: str, split: str) -> str:
  """``<data_dir>/<split>.h5``, with a clear error when it is missing."""
  path = os.path.join(data_dir, f"{split}.h5")
  if not os.path.exists(path):
    present = sorted(f for f in os.listdir(data_dir) if f.endswith(".h5")) \
        if os.path.isdir(data_dir) else []
    raise mpm_io.FormatError(f"{path}: no {split} split; present: {present}")
  return path


__all__ = ["Stats", "Window", "WindowDataset", "load_stats", "solids_of",
           "split_path", "trajectories"]
