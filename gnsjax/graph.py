"""Radius graphs over sand and boundary particles (jax-md cell lists).

The graph network simulator connects every ordered pair of nodes (i, j) with
``|x_i - x_j| < R``, self-pairs included, where nodes are the moving sand
particles and the static boundary (ramp, obstacle) particles of one window.
Edges come from ``jax_md.partition.neighbor_list`` in the ``Sparse`` format: a
cell list over a box, then a distance test, giving ``idx`` [2, capacity] with
rows (neighbour j, particle i), padded with N. The capacity is static; an
update that finds more edges than it holds sets an overflow flag under `jit`,
and ``update_or_reallocate`` reallocates on the host, so no edge is ever
dropped silently.

The one overflow policy: no edge is ever dropped, and no step computed with
a list that overflowed is kept. A program whose list overflowed is rerun
from the first overflowed step with a larger list, never a smaller one.
Where the program can be cut there, it is: the host rollouts
(``gnsjax.rollout``) keep the steps before the overflow and resume from
there (a chunk of a long rollout). A program that is one whole, a
differentiable rollout for inverse design (``gnsjax.design.rollouts``) or
training's pushforward steps (``gnsjax.train``), has no step to resume from
whose gradient or noise stream would be the same, so it is rerun whole;
each grows its list until the rerun fits.

The function pair is ``allocate`` (host, sets capacities from example
positions) and ``update`` (jittable, fixed capacities); ``allocate_batch`` and
``update_batch`` do the same for B windows with a leading batch axis, and
``edges`` / ``batch_edges`` turn a list into (senders, receivers) arrays.

Geometry of the search box (world units, metres). The cell list needs every
position inside [0, box), so world positions are shifted into a box made of:

* the domain ``[x_min, x_max] x [y_min, y_max]`` grown by 2R on each side.
  Real positions are clipped to the domain grown by R before the search only
  (a learned rollout may predict slightly outside the domain); the physics
  never sees the clipped values;
* a *parking strip* below it: a lattice of sites, spaced 2.5R apart and at
  least 2.5R below the domain, with room for ``max_padding`` sites. A batch
  pads each window to a bucketed node count with padding nodes placed at
  ``parking_positions``; each gets its self-edge and nothing else, so padding
  adds O(n) edges, never O(n^2), and never touches a real node. A node lying
  on a parking site (within 1e-3 of the spacing) counts as parked and is not
  clipped; every other node is clipped into the grown domain, even one that
  fell into the strip.

Shapes: N nodes (padded count), B windows, E edge capacity.
"""

import dataclasses
import functools
import math
from typing import Callable, Sequence, Set, Tuple

from absl import logging
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax.neighbors import partition
from gnsjax.neighbors import space

# Parking sites are this many radii apart and at least this far below the
# domain: more than 2R from each other and from the domain, so a site is more
# than R from any clipped real position and from every other site.
_PARKING_SPACING = 2.5
# A node within this fraction of the spacing of a parking site is parked.
_PARKING_TOLERANCE = 1e-3
# Margin of the search box around the domain, in radii.
_MARGIN = 2.0
# Rollout lists' capacities are rounded up to rungs ceil(r^k) (``rounded_up``).
_CAPACITY_RATIO = 2 ** 0.25
# The elementwise maximum of some integers over the processes that each hold
# part of a batch (gnsjax.distributed.agree_max).
Agree = Callable[[Sequence[int]], Sequence[int]]


def _jax_md_rank_promotion():
  """Scopes "allow" to jax-md calls: its cell list multiplies [N, 2] by [2].

  Strict settings elsewhere (the test suite's "raise") still hold.
  """
  return jax.numpy_rank_promotion("allow")


@dataclasses.dataclass(frozen=True)
class GraphSpec:
  """Static description of the radius graph (hashable; changes recompile).

  Attributes:
    radius: connectivity radius R (m); edges join nodes closer than R.
    bounds: the domain ((x_min, x_max), (y_min, y_max)) in metres.
    capacity_multiplier: headroom of allocated edge and cell capacities over
      the occupancy of the positions they were allocated for.
    max_padding: how many padding nodes one window may hold (sizes the parking
      strip, hence the box).
  """
  radius: float
  bounds: Tuple[Tuple[float, float], Tuple[float, float]]
  capacity_multiplier: float = 1.25
  max_padding: int = 1024

  def __post_init__(self):
    try:
      (x_min, x_max), (y_min, y_max) = self.bounds
      bounds = ((float(x_min), float(x_max)), (float(y_min), float(y_max)))
    except (TypeError, ValueError) as e:
      raise ValueError("GraphSpec.bounds must be ((x_min, x_max), (y_min, "
                       f"y_max)); got {self.bounds!r}") from e
    # Accept lists (e.g. from JSON) but store tuples, so the spec hashes.
    object.__setattr__(self, "bounds", bounds)
    object.__setattr__(self, "radius", float(self.radius))
    if not all(map(math.isfinite, bounds[0] + bounds[1])):
      raise ValueError(f"GraphSpec.bounds must be finite; got {bounds}")
    if not (bounds[0][0] < bounds[0][1] and bounds[1][0] < bounds[1][1]):
      raise ValueError("GraphSpec.bounds needs x_min < x_max and y_min < "
                       f"y_max; got {bounds}")
    if not (math.isfinite(self.radius) and self.radius > 0):
      raise ValueError(f"GraphSpec.radius must be > 0; got {self.radius}")
    if not self.capacity_multiplier >= 1.0:
      raise ValueError("GraphSpec.capacity_multiplier must be >= 1; got "
                       f"{self.capacity_multiplier}")
    if int(self.max_padding) != self.max_padding or self.max_padding < 0:
      raise ValueError("GraphSpec.max_padding must be an integer >= 0; got "
                       f"{self.max_padding}")


class _Layout:
  """World-to-box geometry of a spec (see the module docstring)."""

  def __init__(self, spec: GraphSpec):
    r = spec.radius
    (x_min, x_max), (y_min, y_max) = spec.bounds
    self.spacing = _PARKING_SPACING * r
    self.n_cols = int(math.floor((x_max - x_min) / self.spacing)) + 1
    self.n_rows = max(1, -(-spec.max_padding // self.n_cols))
    # Site (col k, row m) sits at first_site + (k, -m) * spacing.
    self.first_site = np.array([x_min, y_min - self.spacing])
    lowest_site = y_min - self.n_rows * self.spacing
    self.origin = np.array([x_min - _MARGIN * r, lowest_site - _MARGIN * r])
    top = np.array([x_max + _MARGIN * r, y_max + _MARGIN * r])
    self.box = (top - self.origin).astype(np.float32)
    self.clip_lo = np.array([x_min - r, y_min - r])
    self.clip_hi = np.array([x_max + r, y_max + r])


@functools.lru_cache(maxsize=None)
def _layout(spec: GraphSpec) -> _Layout:
  return _Layout(spec)


@functools.lru_cache(maxsize=None)
def neighbor_fns(spec: GraphSpec) -> partition.NeighborListFns:
  """The jax-md (allocate, update) pair for a spec, one per spec (cached).

  A free-space Sparse neighbour list with self-pairs, searched by a cell list
  over the extended box. It takes *box* coordinates (``search_positions``);
  prefer this module's ``allocate``/``update``, which convert.

  Args:
    spec: the graph's static description.

  Returns:
    ``partition.NeighborListFns``; the same object for equal specs, so jitted
    updates are not retraced.
  """
  return partition.neighbor_list(
      space.free()[0], _layout(spec).box, spec.radius,
      capacity_multiplier=spec.capacity_multiplier, format=partition.Sparse,
      mask_self=False)


@functools.lru_cache(maxsize=None)
def _cell_list_fns(spec: GraphSpec) -> partition.CellListFns:
  # jax-md builds a new cell-list closure at every allocation and keeps it as
  # a static field of the NeighborList, so each reallocation (even at equal
  # capacities) would retrace jitted updates. The same arguments as
  # jax-md's own call, built once per spec, make equal lists compare equal.
  return partition.cell_list(jnp.asarray(_layout(spec).box), spec.radius,
                             spec.capacity_multiplier)


def _broadcast_row(v: np.ndarray, ndim: int) -> jax.Array:
  """[2] constant as [1, ..., 1, 2] (explicit rank for strict promotion)."""
  return jnp.asarray(v, jnp.float32).reshape((1,) * (ndim - 1) + (2,))


def search_positions(x: jax.Array, spec: GraphSpec) -> jax.Array:
  """Maps world positions into the search box (jittable).

  Nodes on a parking site pass through unchanged; all other nodes are clipped
  to the domain grown by R. Only the neighbour search sees these values.

  Args:
    x: [..., N, 2] world positions (m).
    spec: the graph's static description.

  Returns:
    [..., N, 2] float32 box coordinates, each in [0, box).
  """
  layout = _layout(spec)
  x = jnp.asarray(x, jnp.float32)
  if x.ndim < 2 or x.shape[-1] != 2:
    raise ValueError(f"positions must be [..., N, 2]; got shape {x.shape}")
  row = functools.partial(_broadcast_row, ndim=x.ndim)
  # Lattice coordinates (column, row) of the parking sites.
  lattice = (x - row(layout.first_site)) / layout.spacing
  lattice = lattice * row(np.array([1.0, -1.0]))
  nearest = jnp.round(lattice)
  upper = row(np.array([layout.n_cols - 1, layout.n_rows - 1]))
  parked = jnp.all((jnp.abs(lattice - nearest) < _PARKING_TOLERANCE)
                   & (nearest >= 0) & (nearest <= upper), axis=-1)
  clipped = jnp.clip(x, row(layout.clip_lo), row(layout.clip_hi))
  world = jnp.where(parked[..., None], x, clipped)
  return world - row(layout.origin)


def parking_positions(n: int, spec: GraphSpec) -> np.ndarray:
  """World positions for n padding nodes, one per parking site.

  Sites lie below the domain, more than 2R from it and from each other, so a
  padding node placed on one has its self-edge and no other edge.

  Args:
    n: number of padding nodes, at most ``spec.max_padding`` (rounded up to
      whole rows of sites).
    spec: the graph's static description.

  Returns:
    float32 [n, 2] world positions (m).

  Raises:
    ValueError: when the strip has fewer than n sites.
  """
  layout = _layout(spec)
  capacity = layout.n_cols * layout.n_rows
  if not 0 <= n <= capacity:
    raise ValueError(f"{n} padding nodes do not fit the parking strip "
                     f"({capacity} sites for max_padding={spec.max_padding}); "
                     "raise GraphSpec.max_padding")
  i = np.arange(n)
  offsets = np.stack([i % layout.n_cols, -(i // layout.n_cols)], axis=-1)
  return (layout.first_site + offsets * layout.spacing).astype(np.float32)


def _check_positions(positions, batched: bool) -> jax.Array:
  positions = jnp.asarray(positions, jnp.float32)
  ndim = 3 if batched else 2
  name = "[B, N, 2]" if batched else "[N, 2]"
  if positions.ndim != ndim or positions.shape[-1] != 2 or (
      positions.shape[-2] == 0):
    raise ValueError(f"positions must be {name} with N >= 1; got shape "
                     f"{positions.shape}")
  return positions


def allocate(spec: GraphSpec, positions: jax.Array,
             extra_capacity: int = 0) -> partition.NeighborList:
  """Allocates a neighbour list sized for these positions. Not jittable.

  The edge capacity is ``capacity_multiplier`` times the edges found here,
  plus N * extra_capacity; the cell capacity likewise, plus extra_capacity.
  Changing either capacity recompiles jitted updates.

  Args:
    spec: the graph's static description.
    positions: [N, 2] world positions (m), padding nodes at parking sites.
    extra_capacity: additional edges per node (and slots per cell).

  Returns:
    A Sparse ``partition.NeighborList``: idx [2, E] (neighbour j, particle i)
    padded with N; reference_position [N, 2] in box coordinates.
  """
  positions = _check_positions(positions, batched=False)
  search = search_positions(positions, spec)
  with _jax_md_rank_promotion():
    nbrs = neighbor_fns(spec).allocate(search, extra_capacity=extra_capacity)
  if nbrs.cell_list_fn is not None:
    nbrs = dataclasses.replace(nbrs, cell_list_fn=_cell_list_fns(spec))
  return nbrs


def update(spec: GraphSpec, positions: jax.Array,
           nbrs: partition.NeighborList) -> partition.NeighborList:
  """Rebuilds the edges for new positions at fixed capacity (jittable).

  Args:
    spec: the graph's static description (static under `jit`).
    positions: [N, 2] world positions (m), same N as ``nbrs``.
    nbrs: a list from ``allocate`` (or a previous ``update``).

  Returns:
    The updated list. ``did_buffer_overflow`` is set when the edges or a cell
    did not fit; the edges are then incomplete and the list must be
    reallocated (``update_or_reallocate``). The flag is sticky.
  """
  search = search_positions(positions, spec)
  with _jax_md_rank_promotion():
    return neighbor_fns(spec).update(search, nbrs)


def edges(nbrs: partition.NeighborList,
          n_nodes: int) -> Tuple[jax.Array, jax.Array]:
  """Senders and receivers of a list's edges (jittable).

  Messages flow from sender j to receiver i for each neighbour j of i.

  Args:
    nbrs: an unbatched list, idx [2, E].
    n_nodes: node count of the graph (a Python int, static under `jit`), at
      least the list's N; padding entries get this value (one past the last
      node).

  Returns:
    (senders [E], receivers [E]), int32.
  """
  n = nbrs.reference_position.shape[-2]
  if n_nodes < n:
    raise ValueError(f"n_nodes={n_nodes} is below the list's {n} nodes")
  idx = jnp.where(nbrs.idx < n, nbrs.idx, n_nodes).astype(jnp.int32)
  return idx[0], idx[1]


def _with_capacity(nbrs: partition.NeighborList, capacity: int,
                   cell_capacity) -> partition.NeighborList:
  """The list with idx padded (with N) to `capacity` and a new cell capacity."""
  n = nbrs.reference_position.shape[-2]
  grow = capacity - nbrs.idx.shape[-1]
  if grow < 0:
    raise ValueError(f"cannot shrink capacity {nbrs.idx.shape[-1]} to "
                     f"{capacity}")
  pad = [(0, 0)] * (nbrs.idx.ndim - 1) + [(0, grow)]
  idx = jnp.pad(nbrs.idx, pad, constant_values=n)
  return dataclasses.replace(nbrs, idx=idx, max_occupancy=capacity,
                             cell_list_capacity=cell_capacity)


def _ladder(c: int) -> int:
  """The smallest rung ceil(r^k) >= c of the ladder r = _CAPACITY_RATIO."""
  k = max(0, math.floor(math.log(max(c, 1), _CAPACITY_RATIO)) - 1)
  while math.ceil(_CAPACITY_RATIO ** k) < c:
    k += 1
  return math.ceil(_CAPACITY_RATIO ** k)


def rounded_up(nbrs: partition.NeighborList,
               at_least: partition.NeighborList | None = None
               ) -> partition.NeighborList:
  """The list with its edge and cell capacities rounded up to a ladder.

  Capacities are static shapes, so every size a process meets is compiled
  anew, and XLA:CPU keeps each compiled program's code mapped until the
  process ends: a rollout that reallocated to the exact size it needed
  compiled a program per reallocation, and an evaluation of 21 test
  trajectories ran out of memory maps (about 700 per program, 65530 per
  process) and crashed. On rungs ceil(1.19^k) (at most 19% headroom beyond
  ``capacity_multiplier``) the sizes of all scenes of one particle count fall
  on a few rungs. The edges are unchanged: only padding is added.

  Args:
    nbrs: a list from ``allocate`` or ``allocate_batch``.
    at_least: a list whose capacities the result must not go below (the one
      being replaced), or None.

  Returns:
    The list, idx padded with N to the rounded edge capacity; the edge
    capacity never exceeds the candidates an update produces (N^2, or
    N 3^d times the cell capacity), so updates keep its shapes.
  """
  n = nbrs.reference_position.shape[-2]
  capacity, cell = capacities(nbrs)
  if at_least is not None:
    old_capacity, old_cell = capacities(at_least)
    capacity = max(capacity, old_capacity)
    if cell is not None and old_cell is not None:
      cell = max(cell, old_cell)
  if cell is not None:
    cell = _ladder(cell)
  limit = n * n if cell is None else min(
      n * n, n * 3 ** nbrs.reference_position.shape[-1] * cell)
  return _with_capacity(nbrs, max(capacity, min(_ladder(capacity), limit)),
                        cell)


def capacities(nbrs: partition.NeighborList) -> tuple[int, int | None]:
  """(edge capacity E, cell capacity or None): a list's static sizes, the
  shapes every jitted function taking it is compiled for."""
  return int(nbrs.idx.shape[-1]), nbrs.cell_list_capacity


def _max_cell_capacity(lists) -> int | None:
  capacities = [l.cell_list_capacity for l in lists]
  if any(c is None for c in capacities):
    return None
  return max(capacities)


def _agreed(agree, capacity: int, cell_capacity: int | None):
  """(capacity, cell capacity) at their maximum over the processes."""
  capacity, cell = agree((capacity, -1 if cell_capacity is None else
                          cell_capacity))
  return capacity, None if cell < 0 else cell


def allocate_batch(
    spec: GraphSpec, positions: jax.Array,
    capacities: tuple[int, int | None] | None = None,
    agree: Agree | None = None
) -> partition.NeighborList:
  """Allocates one list per window, at the largest capacities. Not jittable.

  Args:
    spec: the graph's static description.
    positions: [B, N, 2] world positions (m), padding nodes at parking sites.
    capacities: (edge, cell) capacities to allocate at instead (e.g. a
      resumed run's, from ``capacities``): the edges are then built exactly
      as an ``update`` of a list of these sizes builds them, and the list
      is reallocated larger only if they do not fit.
    agree: for a batch split over processes (each holding its windows):
      the elementwise maximum of integers over processes
      (``gnsjax.distributed.agree_max``), so that all allocate the sizes
      one process holding the whole batch would.

  Returns:
    A list whose array leaves carry a leading batch axis: idx [B, 2, E]
    (padded with N), reference_position [B, N, 2], error.code [B].
  """
  positions = _check_positions(positions, batched=True)
  lists = [allocate(spec, p) for p in positions]
  capacity = max(l.max_occupancy for l in lists)
  cell_capacity = _max_cell_capacity(lists)
  if agree is not None:
    capacity, cell_capacity = _agreed(agree, capacity, cell_capacity)
  lists = [_with_capacity(l, capacity, cell_capacity) for l in lists]
  nbrs = jax.tree.map(lambda *leaves: jnp.stack(leaves), *lists)
  if capacities is None:
    return nbrs
  capacity, cell_capacity = capacities
  n = nbrs.reference_position.shape[-2]
  # An empty list of those sizes. jax-md's update keeps the edges of a list
  # whose particles have not moved, so its reference is moved off: the
  # update below builds every edge.
  shell = dataclasses.replace(
      nbrs, idx=jnp.full(nbrs.idx.shape[:-1] + (capacity,), n,
                         nbrs.idx.dtype),
      max_occupancy=capacity, cell_list_capacity=cell_capacity,
      reference_position=nbrs.reference_position + 1.0)
  return update_or_reallocate(spec, positions, shell, batched=True,
                              agree=agree)[0]


def update_batch(spec: GraphSpec, positions: jax.Array,
                 nbrs: partition.NeighborList) -> partition.NeighborList:
  """``update`` mapped over windows (jittable).

  Args:
    spec: the graph's static description (static under `jit`).
    positions: [B, N, 2] world positions (m).
    nbrs: a list from ``allocate_batch``.

  Returns:
    The updated batched list; ``jnp.any(nbrs.did_buffer_overflow)`` tells
    whether any window overflowed.
  """
  return jax.vmap(functools.partial(update, spec))(positions, nbrs)


def batch_edges(nbrs: partition.NeighborList,
                n_nodes: int) -> Tuple[jax.Array, jax.Array]:
  """Edges of B windows as one graph of B * n_nodes nodes (jittable).

  Node i of window b is node b * n_nodes + i.

  Args:
    nbrs: a batched list, idx [B, 2, E].
    n_nodes: node count per window (a Python int, static under `jit`), at
      least the list's N.

  Returns:
    (senders [B * E], receivers [B * E]), int32; padding entries equal
    B * n_nodes.
  """
  n = nbrs.reference_position.shape[-2]
  if n_nodes < n:
    raise ValueError(f"n_nodes={n_nodes} is below the list's {n} nodes")
  n_batch = nbrs.idx.shape[0]
  offsets = (jnp.arange(n_batch, dtype=jnp.int32) * n_nodes)[:, None, None]
  idx = jnp.where(nbrs.idx < n, nbrs.idx + offsets, n_batch * n_nodes)
  idx = idx.astype(jnp.int32)
  return idx[:, 0].reshape(-1), idx[:, 1].reshape(-1)


@functools.partial(jax.jit, static_argnums=0)
def _update_jit(spec, positions, nbrs):
  return update(spec, positions, nbrs)


@functools.partial(jax.jit, static_argnums=0)
def _update_batch_jit(spec, positions, nbrs):
  return update_batch(spec, positions, nbrs)


def update_or_reallocate(
    spec: GraphSpec, positions: jax.Array, nbrs: partition.NeighborList,
    batched: bool = False, agree: Agree | None = None
) -> Tuple[partition.NeighborList, bool]:
  """Updates the list; on overflow reallocates it from `positions`. Host only.

  Runs a jitted ``update`` (``update_batch`` if batched); if that overflowed,
  allocates afresh from the same positions, never below the old capacities,
  so no edge is dropped. A reallocation changes static capacities and so
  recompiles code that takes the list.

  Args:
    spec: the graph's static description.
    positions: [N, 2] (or [B, N, 2] if batched) world positions (m).
    nbrs: the current list (batched if `batched`).
    batched: whether the list and positions carry a batch axis.
    agree: see ``allocate_batch`` (batched only): all processes then
      reallocate when any overflowed, to the same sizes.

  Returns:
    (nbrs, reallocated): the list for `positions`, and whether it was
    reallocated.
  """
  positions = _check_positions(positions, batched=batched)
  new = (_update_batch_jit if batched else _update_jit)(spec, positions, nbrs)
  overflow = bool(jnp.any(new.did_buffer_overflow))
  if agree is not None:
    overflow = bool(agree((int(overflow),))[0])
  if not overflow:
    return new, False
  fresh = (functools.partial(allocate_batch, agree=agree) if batched else
           allocate)(spec, positions)
  capacity = max(fresh.max_occupancy, nbrs.max_occupancy)
  cell_capacity = _max_cell_capacity([fresh, nbrs])
  fresh = _with_capacity(fresh, capacity, cell_capacity)
  logging.info(
      "Neighbour list overflowed; reallocated: edge capacity %d -> %d, cell "
      "capacity %s -> %s.", nbrs.max_occupancy, fresh.max_occupancy,
      nbrs.cell_list_capacity, fresh.cell_list_capacity)
  return fresh, True


def brute_force_edges(positions: np.ndarray,
                      radius: float) -> Set[Tuple[int, int]]:
  """All (sender, receiver) pairs closer than radius, self-pairs included.

  O(N^2) numpy reference (float64) for tests; not for production sizes.

  Args:
    positions: [N, 2] positions.
    radius: connectivity radius.

  Returns:
    The set of directed pairs (j, i) with |x_i - x_j| < radius.
  """
  x = np.asarray(positions, np.float64)
  d2 = np.sum((x[:, None, :] - x[None, :, :]) ** 2, axis=-1)
  senders, receivers = np.nonzero(d2 < radius**2)
  return set(zip(senders.tolist(), receivers.tolist()))
