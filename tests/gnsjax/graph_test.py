"""Tests for `gnsjax.graph`."""

import functools

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import graph

# A window the size of the shared sand block the GNS benchmark times: 1000
# particles on a 0.005 m lattice, jittered by up to 1 mm so that no pair sits
# at exactly R (where float32 and the float64 reference may disagree).
BENCH_RADIUS = 0.015  # m
BENCH_BOUNDS = ((0.1, 0.9), (0.1, 0.9))  # m


def _sand_block():
  """[1000, 2] float32 positions (m) of a 40 x 25 jittered lattice."""
  rng = np.random.default_rng(0)
  i, j = np.meshgrid(np.arange(40), np.arange(25), indexing="ij")
  x = np.stack([0.44 + 0.005 * i.ravel(), 0.1025 + 0.005 * j.ravel()], -1)
  return (x + rng.uniform(-0.001, 0.001, x.shape)).astype(np.float32)

RADIUS = 0.03
BOUNDS = ((0.0, 0.3), (0.0, 0.2))
SPEC = graph.GraphSpec(RADIUS, BOUNDS, max_padding=16)
N_REAL = 40
N_PAD = 16
N = N_REAL + N_PAD  # one padded node count for every test: fewer compiles
POSITION_ATOL = 1e-6  # m; float32 round-off of box coordinates


def _edge_set(senders, receivers, pad):
  """Valid (sender, receiver) pairs; fails on duplicates or bad padding."""
  senders, receivers = np.asarray(senders), np.asarray(receivers)
  valid = senders != pad
  np.testing.assert_array_equal(receivers != pad, valid)
  pairs = set(zip(senders[valid].tolist(), receivers[valid].tolist()))
  assert len(pairs) == int(valid.sum()), "duplicate edges"
  return pairs


def _real_positions(seed):
  """[N_REAL, 2]: sand inside, sand near and just outside the edges, and
  boundary particles along a ramp."""
  rng = np.random.default_rng(seed)
  (x0, x1), (y0, y1) = BOUNDS
  sand = rng.uniform((x0, y0), (x1, y1), (20, 2))
  # Within 0.9 R of each of the four edges, half of them outside the domain.
  offset = rng.uniform(-0.9 * RADIUS, 0.9 * RADIUS, 12)
  along = rng.uniform(0.0, 1.0, 12)
  edge = np.stack([
      np.r_[x0 + offset[:3], x1 + offset[3:6], x0 + along[6:] * (x1 - x0)],
      np.r_[y0 + along[:6] * (y1 - y0), y0 + offset[6:9], y1 + offset[9:]],
  ], axis=-1)
  # Boundary particles: a ramp y = 0.02 + 0.5 (x - 0.1)^2 at 0.013 m steps.
  bx = 0.1 + 0.013 * np.arange(8) + rng.uniform(0, 1e-3)
  ramp = np.stack([bx, 0.02 + 0.5 * (bx - 0.1) ** 2], axis=-1)
  return np.concatenate([sand, edge, ramp]).astype(np.float32)


def _window(seed):
  """[N, 2]: real nodes then padding nodes on parking sites."""
  return np.concatenate([_real_positions(seed),
                         graph.parking_positions(N_PAD, SPEC)])


@functools.partial(jax.jit, static_argnums=0)
def _update_jit(spec, positions, nbrs):
  return graph.update(spec, positions, nbrs)


class GraphSpecTest(absltest.TestCase):

  def test_spec_is_hashable_and_takes_lists(self):
    spec = graph.GraphSpec(0.03, [[0, 0.3], [0, 0.2]], max_padding=16)
    self.assertEqual(spec, SPEC)
    self.assertEqual(hash(spec), hash(SPEC))
    self.assertIs(graph.neighbor_fns(spec), graph.neighbor_fns(SPEC))

  def test_bad_spec_is_refused(self):
    for kwargs in [dict(radius=0.0, bounds=BOUNDS),
                   dict(radius=0.03, bounds=((0.3, 0.0), (0.0, 0.2))),
                   dict(radius=0.03, bounds=(0.0, 0.3)),
                   dict(radius=0.03, bounds=BOUNDS, capacity_multiplier=0.5),
                   dict(radius=0.03, bounds=BOUNDS, max_padding=-1)]:
      with self.assertRaises(ValueError, msg=str(kwargs)):
        graph.GraphSpec(**kwargs)


class GraphTest(absltest.TestCase):

  def test_matches_brute_force_after_allocate_and_update(self):
    x = _window(0)
    nbrs = graph.allocate(SPEC, x, extra_capacity=4)
    self.assertEqual(nbrs.idx.shape[0], 2)
    self.assertFalse(bool(nbrs.did_buffer_overflow))
    senders, receivers = graph.edges(nbrs, N)
    self.assertEqual(senders.dtype, jnp.int32)
    self.assertEqual(_edge_set(senders, receivers, N),
                     graph.brute_force_edges(x, RADIUS))
    for seed in (1, 2):
      y = _window(seed)
      nbrs = _update_jit(SPEC, y, nbrs)
      self.assertFalse(bool(nbrs.did_buffer_overflow))
      self.assertEqual(_edge_set(*graph.edges(nbrs, N), N),
                       graph.brute_force_edges(y, RADIUS), msg=f"seed {seed}")

  def test_edges_pads_with_n_nodes(self):
    nbrs = graph.allocate(SPEC, _window(0))
    senders, receivers = graph.edges(nbrs, N + 3)
    n_edges = len(graph.brute_force_edges(_window(0), RADIUS))
    self.assertEqual(int(np.sum(np.asarray(senders) < N)), n_edges)
    self.assertEqual(set(np.asarray(senders)[n_edges:].tolist()), {N + 3})
    self.assertEqual(set(np.asarray(receivers)[n_edges:].tolist()), {N + 3})
    with self.assertRaises(ValueError):
      graph.edges(nbrs, N - 1)

  def test_search_clips_positions_far_outside(self):
    x = _window(3)
    # Far outside on every side, including deep in the parking strip right
    # next to (but not on) the first parking site.
    x[:5] = [[5.0, 0.1], [-3.0, 0.1], [0.1, 4.0], [0.1, -0.3],
             x[N_REAL] + [0.3 * RADIUS, 0.0]]
    search = np.asarray(graph.search_positions(x, SPEC))
    box = graph._layout(SPEC).box  # pylint: disable=protected-access
    self.assertTrue(np.all((search >= 0) & (search < box)))
    clipped = x.copy()
    clipped[:N_REAL] = np.clip(x[:N_REAL], -RADIUS, (0.3 + RADIUS,
                                                     0.2 + RADIUS))
    # Clipping is a shift of the world: search - clipped is one constant.
    shift = np.broadcast_to(search[:1] - clipped[:1], search.shape)
    np.testing.assert_allclose(search - clipped, shift, atol=POSITION_ATOL,
                               rtol=0)
    nbrs = graph.allocate(SPEC, x)
    pairs = _edge_set(*graph.edges(nbrs, N), N)
    self.assertEqual(pairs, graph.brute_force_edges(clipped, RADIUS))
    self.assertNotIn((N_REAL, 4), pairs)

  def test_padding_nodes_have_only_self_edges(self):
    parked = graph.parking_positions(N_PAD, SPEC)
    self.assertEqual(parked.shape, (N_PAD, 2))
    self.assertEqual(parked.dtype, np.float32)
    (x0, x1), (y0, y1) = BOUNDS
    gaps = np.linalg.norm(parked[:, None] - parked[None], axis=-1)
    self.assertGreater(np.min(gaps + 1.0 * np.eye(N_PAD)), 2 * RADIUS)
    to_domain = np.hypot(np.clip(parked[:, 0], x0, x1) - parked[:, 0],
                         np.clip(parked[:, 1], y0, y1) - parked[:, 1])
    self.assertGreater(np.min(to_domain), 2 * RADIUS)
    # Real nodes pressed against the bottom of the domain, some below it.
    x = _window(4)
    x[:N_REAL, 1] = np.linspace(y0 - 0.99 * RADIUS, y0 + RADIUS, N_REAL)
    senders, receivers = graph.edges(graph.allocate(SPEC, x), N)
    pairs = _edge_set(senders, receivers, N)
    touching_padding = {(s, r) for s, r in pairs if max(s, r) >= N_REAL}
    self.assertEqual(touching_padding, {(i, i) for i in range(N_REAL, N)})
    self.assertEqual(pairs, graph.brute_force_edges(x, RADIUS))

  def test_parking_strip_is_sized_by_max_padding(self):
    spec = graph.GraphSpec(RADIUS, BOUNDS, max_padding=100)
    self.assertLen(graph.parking_positions(100, spec), 100)
    with self.assertRaisesRegex(ValueError, "max_padding"):
      graph.parking_positions(1000, spec)

  def test_overflow_reallocates_without_dropping_edges(self):
    sparse = _window(5)
    sparse[:N_REAL] = np.stack(np.meshgrid(np.linspace(0.0, 0.3, 8),
                                           np.linspace(0.0, 0.2, 5)),
                               axis=-1).reshape(-1, 2)
    dense = _window(5)
    dense[:N_REAL] = np.random.default_rng(5).uniform(
        (0.1, 0.1), (0.13, 0.12), (N_REAL, 2))
    nbrs = graph.allocate(SPEC, sparse)
    overflowed = _update_jit(SPEC, dense, nbrs)
    self.assertTrue(bool(overflowed.did_buffer_overflow))
    with self.assertLogs(level="INFO") as logs:
      grown, reallocated = graph.update_or_reallocate(SPEC, dense, nbrs)
    self.assertTrue(reallocated)
    self.assertIn(f"edge capacity {nbrs.max_occupancy} -> "
                  f"{grown.max_occupancy}", "\n".join(logs.output))
    self.assertGreater(grown.max_occupancy, nbrs.max_occupancy)
    self.assertFalse(bool(grown.did_buffer_overflow))
    self.assertEqual(_edge_set(*graph.edges(grown, N), N),
                     graph.brute_force_edges(dense, RADIUS))
    # The grown list now holds both configurations without reallocating.
    for x in (sparse, dense):
      again, reallocated = graph.update_or_reallocate(SPEC, x, grown)
      self.assertFalse(reallocated)
      self.assertEqual(_edge_set(*graph.edges(again, N), N),
                       graph.brute_force_edges(x, RADIUS))

  def test_rounded_up_capacities_are_few_and_keep_every_edge(self):
    # Twelve scenes of one density: exact allocations differ in size, the
    # rounded ones share a rung or two, never smaller; an update at the
    # rounded sizes finds every edge.
    rng = np.random.default_rng(7)
    exact, rounded = set(), set()
    for _ in range(12):
      x = _window(60)
      x[:N_REAL] = 0.1 + (x[:N_REAL] - 0.1) * 0.5
      x[:N_REAL] += rng.uniform(-5e-3, 5e-3, (N_REAL, 2))
      fresh = graph.allocate(SPEC, x)
      up = graph.rounded_up(fresh)
      exact.add(graph.capacities(fresh)[0])
      rounded.add(graph.capacities(up))
      self.assertGreaterEqual(up.max_occupancy, fresh.max_occupancy)
      self.assertLessEqual(up.max_occupancy, 1.2 * fresh.max_occupancy + 1)
      self.assertGreaterEqual(up.cell_list_capacity, fresh.cell_list_capacity)
      updated = _update_jit(SPEC, x, up)
      self.assertFalse(bool(updated.did_buffer_overflow))
      self.assertEqual(updated.idx.shape, up.idx.shape)
      self.assertEqual(_edge_set(*graph.edges(updated, N), N),
                       graph.brute_force_edges(x, RADIUS))
    self.assertGreaterEqual(len(exact), 6)
    self.assertLessEqual(len(rounded), 3, rounded)
    # Never below the list being replaced.
    dense = x.copy()
    dense[:N_REAL] = 0.1 + (dense[:N_REAL] - 0.1) * 0.2
    big = graph.rounded_up(graph.allocate(SPEC, dense))
    small = graph.rounded_up(graph.allocate(SPEC, x), at_least=big)
    self.assertEqual(graph.capacities(small), graph.capacities(big))

  def test_batch_matches_per_window_graphs(self):
    n_batch = 3
    x = np.stack([_window(10 + b) for b in range(n_batch)])
    # Windows pad differently: window 1 has 6 real nodes more.
    x[1, N_REAL:N_REAL + 6] = _real_positions(30)[:6]
    nbrs = graph.allocate_batch(SPEC, x)
    self.assertEqual(nbrs.idx.shape[:2], (n_batch, 2))
    self.assertEqual(nbrs.reference_position.shape, (n_batch, N, 2))
    y = np.stack([_window(20 + b) for b in range(n_batch)])
    y[2, :N_REAL] = y[2, :N_REAL] * 0.2 + 0.1  # dense: overflows
    updated = jax.jit(graph.update_batch, static_argnums=0)(SPEC, y, nbrs)
    np.testing.assert_array_equal(
        np.asarray(updated.did_buffer_overflow) != 0, [False, False, True])
    updated, reallocated = graph.update_or_reallocate(SPEC, y, nbrs,
                                                      batched=True)
    self.assertTrue(reallocated)
    for positions, lists in ((x, nbrs), (y, updated)):
      pairs = _edge_set(*graph.batch_edges(lists, N), n_batch * N)
      expected = set()
      for b in range(n_batch):
        expected |= {(s + b * N, r + b * N)
                     for s, r in graph.brute_force_edges(positions[b],
                                                         RADIUS)}
      self.assertEqual(pairs, expected)

  def test_allocation_at_stored_capacities_equals_the_grown_list(self):
    # A resumed training run re-allocates its lists at the capacities its
    # checkpoint stored: the list (edge order included, which fixes the
    # rounding of every sum over edges) must be the one the uninterrupted
    # run's grown list gives by an update.
    sparse = np.stack([_window(40 + b) for b in range(2)])
    dense = sparse.copy()
    dense[1, :N_REAL] = dense[1, :N_REAL] * 0.3 + 0.1  # more edges
    grown, reallocated = graph.update_or_reallocate(
        SPEC, dense, graph.allocate_batch(SPEC, sparse), batched=True)
    self.assertTrue(reallocated)
    uninterrupted, _ = graph.update_or_reallocate(SPEC, sparse, grown,
                                                  batched=True)
    fresh = graph.allocate_batch(SPEC, sparse)
    restored = graph.allocate_batch(SPEC, sparse, graph.capacities(grown))
    self.assertLess(graph.capacities(fresh)[0], graph.capacities(grown)[0])
    self.assertEqual(graph.capacities(restored), graph.capacities(grown))
    self.assertEqual(jax.tree.structure(restored),
                     jax.tree.structure(uninterrupted))
    jax.tree.map(np.testing.assert_array_equal, restored, uninterrupted)
    # Sizes too small for these positions: reallocated, no edge dropped.
    small = graph.allocate_batch(SPEC, dense, graph.capacities(fresh))
    self.assertFalse(bool(jnp.any(small.did_buffer_overflow)))
    self.assertEqual(_edge_set(*graph.batch_edges(small, N), 2 * N),
                     _edge_set(*graph.batch_edges(grown, N), 2 * N))

  def test_update_does_not_retrace(self):
    traces = []

    @functools.partial(jax.jit, static_argnums=0)
    def update_fn(spec, positions, nbrs):
      traces.append(positions.shape)
      return graph.update(spec, positions, nbrs)

    nbrs = graph.allocate(SPEC, _window(6))
    for seed in (7, 8):
      nbrs = update_fn(SPEC, _window(seed), nbrs)
    # A fresh allocation with the same capacities is the same static list.
    again = graph.allocate(SPEC, _window(6))
    self.assertEqual(jax.tree.structure(again),
                     jax.tree.structure(graph.allocate(SPEC, _window(6))))
    update_fn(SPEC, _window(9), again)
    self.assertLen(traces, 1)

  def test_benchmark_sized_graph_is_the_brute_force_graph(self):
    x = _sand_block()
    spec = graph.GraphSpec(BENCH_RADIUS, BENCH_BOUNDS)
    nbrs = graph.allocate(spec, x)
    pairs = _edge_set(*graph.edges(nbrs, len(x)), len(x))
    self.assertGreater(len(pairs), 20 * len(x))  # ~25 neighbours each
    self.assertEqual(pairs, graph.brute_force_edges(x, BENCH_RADIUS))


if __name__ == "__main__":
  absltest.main()
