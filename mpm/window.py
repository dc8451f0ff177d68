"""Which window of the grid a chunk of frames updates (host side).

``mpm.simulate_setups`` runs each chunk of frames on a window of the grid
that follows the sand (``mpm.solver.rollout_windowed``); this picks its
static size from the sand's extent and reach, on a short ladder so that a
run compiles for a few sizes at most, and leaves small grids whole, where
the window's own work costs more than the nodes it skips
(docs/performance.md).
"""

import numpy as np

from mpm import solver
from mpm import transfer

# Window sizes per axis: multiples of an eighth of the grid (at least 8
# nodes), so a run compiles for a few sizes at most.
WINDOW_STEPS = 8
# A window that would cover this fraction of the grid's nodes or more: the
# whole grid instead (one program fewer, nothing to save).
WINDOW_MAX_FRACTION = 0.6
# Grids with fewer nodes run whole: there the window's own work costs more
# than the nodes it skips (this CPU, docs/performance.md, since the cheaper
# substep of 2026-11-26: 1.14x slower at 5.5 thousand nodes, 0.92x at 8.9,
# 0.82x at 20 thousand; before it the crossover was near 40 thousand).
WINDOW_MIN_NODES = 8_000
# Boundary capacities are rounded up to a power of two, at least this, so
# that the scenes of a study or a dataset share a few compiled programs.
CAPACITY_MIN = 64


def window_size(spec: transfer.GridSpec, extent: np.ndarray,
                reach: np.ndarray) -> tuple[int, int] | None:
  """The grid window (nodes per axis) for sand of ``extent`` [2] (m) that
  may grow by ``reach`` [2] (m) on each side within one frame and spread
  over a chunk: the extent plus the reach plus the stencil, rounded up to
  the ladder; None when the whole grid is about as cheap (a grid of fewer
  than ``WINDOW_MIN_NODES`` nodes, or a window of most of it)."""
  if spec.n_nodes < WINDOW_MIN_NODES:
    return None
  need = np.ceil((np.asarray(extent) + 2 * np.asarray(reach)) / spec.dx) + 6
  size = []
  for n, full in zip(need, spec.shape):
    step = max(8, -(-full // WINDOW_STEPS))
    size.append(int(min(full, -(-int(n) // step) * step)))
  if size[0] * size[1] >= WINDOW_MAX_FRACTION * spec.n_nodes:
    return None
  return tuple(size)


def larger(spec: transfer.GridSpec,
            size: tuple[int, int]) -> tuple[int, int] | None:
  """The window two ladder steps larger on each axis (None: the grid)."""
  grown = tuple(min(full, n + 2 * max(8, -(-full // WINDOW_STEPS)))
                for n, full in zip(size, spec.shape))
  if grown[0] * grown[1] >= WINDOW_MAX_FRACTION * spec.n_nodes:
    return None
  return grown


def chunk_window(spec: transfer.GridSpec, extent: np.ndarray,
                  reach: np.ndarray, before: tuple[int, int] | None, *,
                  first_chunk: bool) -> tuple[int, int] | None:
  """A chunk's window: ``window_size``'s, never smaller than the last
  chunk's (``before``), and the whole grid (None) once a chunk ran whole:
  a deposit rarely shrinks much, and each new size is one more program to
  compile."""
  if before is None and not first_chunk:
    return None
  wanted = window_size(spec, extent, reach)
  if wanted is None or before is None:
    return wanted
  return tuple(map(max, wanted, before))


def boundary_count(index: np.ndarray, spec: transfer.GridSpec,
                   size: tuple[int, int]) -> int:
  """The most boundary entries (``BoundaryField.index`` [..., B], flat node
  indices, 0 for padding; a leading axis of scenes takes the largest) that
  any window of ``size`` nodes inside the grid holds."""
  index = np.asarray(index).reshape(-1, np.shape(index)[-1])
  wx, wy = size
  most = 0
  for row in index:
    mask = np.zeros(spec.shape, np.int64)
    mask.flat[row[row > 0]] = 1
    # Summed-area table: entries in every placement of the window at once.
    table = np.pad(mask.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    counts = (table[wx:, wy:] - table[:-wx, wy:] - table[wx:, :-wy] +
              table[:-wx, :-wy])
    most = max(most, int(counts.max()))
  return most


def boundary_capacity(index: np.ndarray, spec: transfer.GridSpec,
                      size: tuple[int, int]) -> int:
  """``boundary_count`` rounded up to a power of two, at least
  ``CAPACITY_MIN``, at most B: the static number of entries a windowed
  frame applies the conditions to (``boundary.window``)."""
  most = boundary_count(index, spec, size)
  return min(np.shape(index)[-1],
             max(CAPACITY_MIN, 1 << max(most - 1, 0).bit_length()))


def extent(state: solver.MPMState) -> np.ndarray:
  """[..., 2] the sand's bounding-box size (m), per scene."""
  x, active = np.asarray(state.x), np.asarray(state.volume) > 0
  lo = np.where(active[..., None], x, np.inf).min(-2)
  hi = np.where(active[..., None], x, -np.inf).max(-2)
  return hi - lo
