"""Host-side assembly of training windows into padded batches (numpy).

A window's nodes are its moving particles, then (if boundary particles are
modelled) the boundary particles that are within the connectivity radius of
a moving particle in the last input frame (the only boundary particles that
get an edge: a scene pays only for what it contains), then padding. Each
window carries its scene's SDF grid, from which the model sees the solids.
Each batch is padded to a multiple of ``node_bucket`` nodes so that training
compiles a handful of times.

Shapes: B windows, C + 1 frames (C inputs and the target), N padded nodes.
"""

from typing import Callable, NamedTuple, Sequence

import numpy as np

from gnsjax import data
from gnsjax import graph


class Batch(NamedTuple):
  """Padded windows.

  Attributes:
    positions: float32 [B, C + 1, N, 2] (m); static nodes repeat their
      position, padding nodes sit at ``graph.parking_positions``.
    particle_type: int32 [B, N] (0 for padding).
    moving: bool [B, N], the particles the model predicts (loss, noise).
    solids: float32 [B, Gx, Gy, 3] the windows' ``mpm.SDFGrid`` values.
  """
  positions: np.ndarray
  particle_type: np.ndarray
  moving: np.ndarray
  solids: np.ndarray


def near_boundary(moving: np.ndarray, boundary: np.ndarray,
                  radius: float) -> np.ndarray:
  """bool [Nb]: boundary particles within ``radius`` of any moving one.

  Args:
    moving: [N, 2]; boundary: [Nb, 2] (m).
  """
  if len(boundary) == 0 or len(moving) == 0:
    return np.zeros(len(boundary), bool)
  # Bin the moving particles in cells of size radius; check the 3x3 cells.
  lo = np.minimum(moving.min(0), boundary.min(0))
  cells = {}
  for key, idx in zip(map(tuple, np.floor((moving - lo) / radius).astype(int)),
                      range(len(moving))):
    cells.setdefault(key, []).append(idx)
  keep = np.zeros(len(boundary), bool)
  bcell = np.floor((boundary - lo) / radius).astype(int)
  r2 = radius * radius
  for b, (cx, cy) in enumerate(bcell):
    near = [i for dx in (-1, 0, 1) for dy in (-1, 0, 1)
            for i in cells.get((cx + dx, cy + dy), ())]
    if near and np.min(np.sum((moving[near] - boundary[b])**2, -1)) < r2:
      keep[b] = True
  return keep


def window_nodes(window: data.Window, radius: float, boundary: bool = True):
  """Nodes of one window: (positions [C + 1, n, 2], types [n], moving [n])."""
  frames = window.positions.shape[0]
  if boundary:
    keep = near_boundary(window.positions[-2], window.boundary_positions,
                         radius)
  else:
    keep = np.zeros(len(window.boundary_positions), bool)
  fixed = window.boundary_positions[keep]
  positions = np.concatenate(
      [window.positions,
       np.broadcast_to(fixed[None], (frames,) + fixed.shape)], 1)
  types = np.concatenate([window.particle_type, window.boundary_type[keep]])
  moving = np.arange(len(types)) < window.positions.shape[1]
  return positions.astype(np.float32), types.astype(np.int32), moving


def make_batch(windows: Sequence[data.Window], spec: graph.GraphSpec,
               node_bucket: int = 128, boundary: bool = True,
               sdf_spacing: float = 0.005,
               agree: Callable[[Sequence[int]], Sequence[int]] | None = None
               ) -> Batch:
  """Pads the windows' nodes to one bucketed count and stacks them, with
  each window's SDF grid at ``sdf_spacing`` (m).

  ``agree`` (``gnsjax.distributed.agree_max``), when these windows are one
  process's share of a batch: the count is then the largest over all
  processes, the count one process holding the whole batch pads to."""
  nodes = [window_nodes(w, spec.radius, boundary) for w in windows]
  n = max(len(t) for _, t, _ in nodes)
  n = -(-n // node_bucket) * node_bucket
  if agree is not None:
    (n,) = agree((n,))
  positions, types, moving = [], [], []
  for p, t, m in nodes:
    k = n - len(t)
    park = graph.parking_positions(k, spec)
    positions.append(np.concatenate(
        [p, np.broadcast_to(park[None], (p.shape[0], k, 2))], 1))
    types.append(np.concatenate([t, np.zeros(k, np.int32)]))
    moving.append(np.concatenate([m, np.zeros(k, bool)]))
  solids = np.stack([data.solids_of(w.scene, sdf_spacing).values
                     for w in windows])
  return Batch(np.stack(positions).astype(np.float32), np.stack(types),
               np.stack(moving), solids)


class DeviceWindows:
  """A whole split on the device; batches of windows gathered under `jit`.

  The host batch (``make_batch``) reads each window from HDF5 and pads it in
  numpy (~150 batches/s measured), far slower than an accelerator's training
  step. Here every trajectory is stored once on the device, padded to one
  bucketed node count (padding nodes parked, ``graph.parking_positions``),
  with its SDF grid; a batch is one jitted gather by (trajectory, start)
  indices, which the host computes from ``data.WindowDataset.locate``.

  Models with boundary particles need a per-window choice of them
  (``window_nodes``) and use ``make_batch``. Needs every trajectory of the
  split to have the same frame count. Memory: S F N 2 floats for positions
  and S Gx Gy 3 for the grids (the paper dataset: ~4.8 + 3.8 GB).

  Shapes: S trajectories, F frames, N padded nodes, B windows.
  """

  def __init__(self, path: str, spec: graph.GraphSpec, *, input_frames: int,
               frame_stride: int = 1, node_bucket: int = 128,
               sdf_spacing: float = 0.005):
    """
    Args:
      path: a split file.
      spec: the graph's static description (parking sites).
      input_frames: frames per window before the target (C, plus any
        pushforward steps).
      frame_stride: k, stored frames between a window's frames.
      node_bucket: N is the largest sand count rounded up to this.
      sdf_spacing: the SDF grids' node spacing (m).
    """
    import jax  # pylint: disable=g-import-not-at-top
    trajectories = list(data.trajectories(path))
    frames = {len(t.positions) for t in trajectories}
    if len(frames) != 1:
      raise ValueError(f"{path}: DeviceWindows needs one frame count for "
                       f"all trajectories; found {sorted(frames)}")
    n = max(t.positions.shape[1] for t in trajectories)
    n = -(-n // node_bucket) * node_bucket
    positions, types, moving, solids = [], [], [], []
    for t in trajectories:
      k = n - t.positions.shape[1]
      park = graph.parking_positions(k, spec)
      positions.append(np.concatenate(
          [t.positions, np.broadcast_to(park[None], (len(t.positions), k, 2))],
          1))
      types.append(np.concatenate([t.particle_type, np.zeros(k, np.int32)]))
      moving.append(np.arange(n) < t.positions.shape[1])
      solids.append(data.solids_of(t.scene, sdf_spacing).values)
    self.positions = jax.device_put(np.stack(positions).astype(np.float32))
    self.types = jax.device_put(np.stack(types).astype(np.int32))
    self.moving = jax.device_put(np.stack(moving))
    self.solids = jax.device_put(np.stack(solids).astype(np.float32))
    self.offsets = jax.device_put(
        np.arange(input_frames + 1, dtype=np.int32) * frame_stride)
    self._gather = jax.jit(_gather_windows)

  def batch(self, trajectory: np.ndarray, start: np.ndarray) -> Batch:
    """The windows (trajectory[b], start[b]) as a ``Batch`` of device
    arrays: positions [B, C + 1, N, 2], types, moving, solids."""
    return self._gather(self.positions, self.types, self.moving, self.solids,
                        self.offsets, np.asarray(trajectory, np.int32),
                        np.asarray(start, np.int32))


def _gather_windows(positions, types, moving, solids, offsets, trajectory,
                    start) -> Batch:
  frames = start[:, None] + offsets[None]                     # [B, C + 1]
  return Batch(positions[trajectory[:, None], frames], types[trajectory],
               moving[trajectory], solids[trajectory])
