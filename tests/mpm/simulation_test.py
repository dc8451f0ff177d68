"""Tests for `mpm.simulation`."""

import dataclasses
from unittest import mock

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from mpm import boundary
from mpm import programs
from mpm import solver
from mpm import window

FLOOR = 0.05


def _scene(name="a", box=(0.1, 0.12, 0.2, 0.18), obstacles=(), **kw):
  """Sand dropped onto a flat floor (with obstacles) in a 0.3 m box."""
  d = {"name": name, "domain": {"width": 0.3, "height": 0.3},
       "ramp": {"kind": "polynomial", "coefficients": [FLOOR]},
       "obstacles": list(obstacles),
       "granular": {"box": list(box), "spacing": 0.01},
       "material": {"density": 1500.0, "youngs_modulus": 1e5,
                    "poisson_ratio": 0.3, "friction_angle_deg": 35.0},
       "solver": {"dx": 0.02, "cfl": 0.4}, "num_frames": 9,
       "frame_dt": 0.01}
  d.update(kw)
  return mpm.Scene.from_dict(d)


class SimulateTest(parameterized.TestCase):

  def test_result(self):
    scene = _scene()
    x0 = mpm.granular_particles(scene)
    frames = []
    result = mpm.simulate(scene, chunk_frames=3, progress=frames.append)
    self.assertEqual(result.positions.shape, (9, len(x0), 2))
    self.assertEqual(result.positions.dtype, np.float32)
    np.testing.assert_array_equal(result.positions[0], x0)
    self.assertEqual(result.max_speed.shape, (9,))
    self.assertEqual(result.max_speed[0], 0.0)
    self.assertEqual(frames, [3, 6, 8])
    self.assertEqual(result.scene, scene)
    bpos, btypes = mpm.boundary_particles(scene)
    np.testing.assert_array_equal(result.boundary_positions, bpos)
    np.testing.assert_array_equal(result.boundary_types, btypes)
    self.assertGreaterEqual(result.n_substeps, 1)
    self.assertGreater(result.wall_time_s, 0.0)
    # Falling sand: the largest speed grows like g t until it lands.
    self.assertGreater(result.max_speed[3], result.max_speed[1])

  def test_past_the_programs_kept_all_are_dropped_and_runs_stay_equal(self):
    scenes = [_scene("a"), _scene("b", solver={"dx": 0.015, "cfl": 0.4})]
    first = [mpm.simulate(s, chunk_frames=4) for s in scenes]
    with mock.patch.object(programs, "MAX_COMPILED", 1), \
        mock.patch.dict(programs._compiled, clear=True):
      again = [mpm.simulate(s, chunk_frames=4) for s in scenes]
      self.assertLen(programs._compiled, 1)
    for f, a in zip(first, again):
      np.testing.assert_array_equal(a.positions, f.positions)
    self.assertGreater(again[0].compile_time_s, 0.0)   # compiled anew

  def test_chunking_does_not_change_the_trajectory(self):
    scene = _scene()
    whole = mpm.simulate(scene)
    chunked = mpm.simulate(scene, chunk_frames=3)
    # The same float32 operations; only the scan length differs.
    np.testing.assert_allclose(chunked.positions, whole.positions, atol=1e-6,
                               rtol=0)

  def test_padding_does_not_change_the_trajectory(self):
    scene = _scene(obstacles=[{"shape": "semicircle", "x": 0.15,
                               "radius": 0.03}])
    padded = mpm.simulate_setups([mpm.setup(scene)])[0]
    exact = mpm.simulate_setups([mpm.setup(scene, particle_bucket=1,
                                           node_bucket=1)])[0]
    # Zero-volume particles and zero-weight nodes are no-ops.
    np.testing.assert_allclose(padded.positions, exact.positions, atol=1e-5,
                               rtol=0)

  def test_rejects_positions_outside_the_domain(self):
    scene = _scene()
    with self.assertRaisesRegex(ValueError, "x0"):
      mpm.setup(scene, np.array([[0.1, 0.2], [0.4, 0.2]]))


class BatchTest(absltest.TestCase):

  def test_batch_matches_separate_runs(self):
    # Different particle counts (padded to one), obstacles and friction.
    scenes = [
        _scene("a", box=(0.1, 0.12, 0.2, 0.18)),
        _scene("b", box=(0.05, 0.12, 0.25, 0.22), boundary_friction=0.2,
               obstacles=[{"shape": "rectangle", "x": 0.15, "width": 0.04,
                           "height": 0.04}],
               material={"density": 1500.0, "youngs_modulus": 1e5,
                         "poisson_ratio": 0.3, "friction_angle_deg": 25.0}),
    ]
    # One program for both (no size buckets): the padding is exercised.
    batch = mpm.simulate_batch(scenes, bucket_ratio=None, max_batch=2)
    for scene, result in zip(scenes, batch):
      single = mpm.simulate(scene)
      self.assertEqual(result.scene, scene)
      self.assertEqual(result.n_substeps, single.n_substeps)
      self.assertEqual(result.positions.shape, single.positions.shape)
      # The vmapped and single programs may fuse and round differently:
      # ~30 float32 ulps of a 0.3 m position (measured: 3e-8 m).
      np.testing.assert_allclose(result.positions, single.positions,
                                 atol=1e-6, rtol=0)
      np.testing.assert_allclose(result.max_speed, single.max_speed,
                                 atol=1e-5, rtol=0)
    self.assertNotEqual(batch[0].positions.shape, batch[1].positions.shape)

  def test_size_buckets_are_the_fewest_groups_within_the_ratio(self):
    rng = np.random.default_rng(0)
    for _ in range(30):
      counts = list(rng.integers(100, 400, rng.integers(1, 9)))
      groups = mpm.simulation.size_buckets(counts, 1.25)
      self.assertEqual(sorted(i for g in groups for i in g),
                       list(range(len(counts))))
      for g in groups:
        self.assertLessEqual(max(counts[i] for i in g),
                             1.25 * min(counts[i] for i in g))
      # Brute force: the fewest groups is the fewest intervals of the
      # sorted counts that each start at a count and span 1.25x.
      fewest, covered = 0, -1
      for c in sorted(counts):
        if c > covered:
          fewest, covered = fewest + 1, 1.25 * c
      self.assertEqual(len(groups), fewest)

  def test_buckets_of_a_batch_come_back_in_order(self):
    scenes = [_scene("big", box=(0.05, 0.12, 0.25, 0.22)),
              _scene("small", box=(0.1, 0.12, 0.2, 0.18)),
              _scene("big2", box=(0.06, 0.12, 0.26, 0.22))]
    results = mpm.simulate_batch(scenes, max_batch=3)
    self.assertEqual([r.scene.name for r in results], ["big", "small", "big2"])
    for scene, result in zip(scenes, results):
      np.testing.assert_allclose(result.positions,
                                 mpm.simulate(scene).positions, atol=1e-6,
                                 rtol=0)

  def test_batch_uses_the_largest_substep_count(self):
    soft = _scene("soft")
    stiff = _scene("stiff", material={"density": 1500.0,
                                      "youngs_modulus": 1e6,
                                      "poisson_ratio": 0.3,
                                      "friction_angle_deg": 35.0})
    n_soft, n_stiff = (mpm.setup(s).n_substeps for s in (soft, stiff))
    self.assertLess(n_soft, n_stiff)
    results = mpm.simulate_batch([soft, stiff], max_batch=2)
    self.assertEqual([r.n_substeps for r in results], [n_stiff, n_stiff])
    self.assertTrue(all(np.all(np.isfinite(r.positions)) for r in results))
    # At most max_batch per program: each alone keeps its own count, and
    # its result is simulate's.
    alone = mpm.simulate_batch([soft, stiff], max_batch=1)
    self.assertEqual([r.n_substeps for r in alone], [n_soft, n_stiff])
    np.testing.assert_array_equal(alone[0].positions,
                                  mpm.simulate(soft).positions)
    with self.assertRaisesRegex(ValueError, "max_batch = 0; allowed"):
      mpm.simulate_batch([soft], max_batch=0)
    # The CPU's default is one scene per program.
    self.assertEqual(mpm.simulation.default_max_batch(), 1)

  def test_mismatched_setups_are_rejected(self):
    a = mpm.setup(_scene("a"))
    b = mpm.setup(_scene("b", num_frames=5))
    with self.assertRaisesRegex(ValueError, "'b' differs from 'a'"):
      mpm.simulate_setups([a, b])


# How far the window's positions may be from the whole grid's (m). The same
# operations on other array shapes are not the same arithmetic: XLA may
# vectorise and contract them differently, and how depends on the CPU it
# compiles for (measured on these tests' scenes: 1.6e-7 m after 30 frames on
# one machine, 2.5e-6 m for the batch on an AMD EPYC; the paper scene and the
# cost benchmark's columns: 0). Ten micrometres, a thousandth of a particle
# spacing, bounds that and still catches a wrong stencil or boundary.
WINDOW_TOLERANCE_M = 1e-5


def _wide(name="wide", box=(0.04, 0.06, 0.14, 0.14), **kw):
  """Sand slumping on the floor at the left of a domain large enough that
  the grid window is a part of the grid (dx 0.02 m: 52 x 30 nodes)."""
  return _scene(name, box=box, domain={"width": 0.9, "height": 0.45},
                num_frames=31, **kw)


class GridWindowTest(absltest.TestCase):
  """``grid_window``: the grid work follows the sand, the result does not
  change. (Small grids run whole by default; these tests window them.)"""

  def setUp(self):
    super().setUp()
    patch = mock.patch.object(window, "WINDOW_MIN_NODES", 0)
    patch.start()
    self.addCleanup(patch.stop)

  def _sizes_used(self, scene, **kwargs):
    """(result, the window sizes chosen per chunk)."""
    chosen = []
    original = window.window_size

    def spy(*args):
      chosen.append(original(*args))
      return chosen[-1]
    with mock.patch.object(window, "window_size", spy):
      return mpm.simulate(scene, chunk_frames=10, **kwargs), chosen

  def test_the_window_gives_the_whole_grids_positions_bit_for_bit(self):
    scene = _wide(obstacles=[{"shape": "semicircle", "x": 0.3,
                              "radius": 0.04}])
    windowed, chosen = self._sizes_used(scene)
    whole = mpm.simulate(scene, chunk_frames=10, grid_window=False)
    spec = mpm.setup(scene).spec
    self.assertTrue(chosen and all(c is not None for c in chosen))
    self.assertLess(chosen[0][0] * chosen[0][1], spec.n_nodes / 4)
    # The sand spreads: the window grows, never shrinks.
    self.assertGreater(chosen[-1][0], chosen[0][0])
    # The same operations on other array shapes: XLA may vectorise (and
    # contract into FMAs) differently, so a few float32 ulps (measured:
    # 1.6e-7 m after 30 frames; the paper scene: 0 after 600).
    np.testing.assert_allclose(windowed.positions, whole.positions,
                               atol=WINDOW_TOLERANCE_M, rtol=0)
    np.testing.assert_allclose(windowed.max_speed, whole.max_speed,
                               atol=1e-5, rtol=0)
    self.assertGreater(np.ptp(windowed.positions[-1, :, 0]), 0.12)

  def test_a_window_the_sand_leaves_is_grown_and_the_chunk_run_again(self):
    scene = _wide()
    with mock.patch.object(window, "window_size",
                           lambda spec, extent, reach: (8, 8)):
      grown = mpm.simulate(scene, chunk_frames=10)
    whole = mpm.simulate(scene, chunk_frames=10, grid_window=False)
    np.testing.assert_allclose(grown.positions, whole.positions,
                               atol=WINDOW_TOLERANCE_M, rtol=0)

  def test_a_batch_on_windows_equals_it_on_the_whole_grid(self):
    scenes = [_wide("a"), _wide("b", box=(0.5, 0.06, 0.62, 0.12))]
    windowed = mpm.simulate_batch(scenes, chunk_frames=10, max_batch=2)
    whole = mpm.simulate_batch(scenes, chunk_frames=10, grid_window=False,
                               max_batch=2)
    for w, f in zip(windowed, whole):
      np.testing.assert_allclose(w.positions, f.positions,
                                 atol=WINDOW_TOLERANCE_M, rtol=0)

  def test_window_sizes_come_from_a_ladder_and_large_ones_are_the_grid(self):
    spec = mpm.setup(_wide()).spec                  # 52 x 30 nodes
    step = [max(8, -(-n // window.WINDOW_STEPS)) for n in spec.shape]
    size = window.window_size(spec, np.array([0.1, 0.08]),
                                  np.array([0.02, 0.02]))
    # (0.1 + 0.04) / 0.02 + 6 = 13 nodes and (0.08 + 0.04) / 0.02 + 6 = 12,
    # rounded up to the steps.
    self.assertEqual(size, (-(-13 // step[0]) * step[0],
                            -(-12 // step[1]) * step[1]))
    self.assertIsNone(window.window_size(spec, np.array([0.8, 0.3]),
                                             np.array([0.02, 0.02])))
    with mock.patch.object(window, "WINDOW_MIN_NODES", spec.n_nodes + 1):
      self.assertIsNone(window.window_size(spec, np.array([0.1, 0.08]),
                                               np.array([0.02, 0.02])))


  def test_a_chunks_window_never_shrinks_and_whole_stays_whole(self):
    spec = mpm.setup(_wide()).spec
    small, reach = np.array([0.1, 0.08]), np.array([0.02, 0.02])
    first = window.chunk_window(spec, small, reach, None, first_chunk=True)
    self.assertIsNotNone(first)
    bigger = (first[0] + 8, first[1])
    self.assertEqual(window.chunk_window(spec, small, reach, bigger,
                                         first_chunk=False), bigger)
    # Once a chunk ran on the whole grid, later chunks do too.
    self.assertIsNone(window.chunk_window(spec, small, reach, None,
                                          first_chunk=False))


class WindowedSolverTest(absltest.TestCase):
  """``solver.rollout_windowed`` against ``solver.rollout``."""

  def test_equal_while_the_sand_stays_in_and_flagged_when_it_leaves(self):
    s = mpm.setup(_wide())
    args = (s.state, s.params, s.field)
    whole = jax.jit(solver.rollout, static_argnums=(3, 4, 5))(
        *args, s.spec, 10, s.n_substeps)
    windowed = jax.jit(solver.rollout_windowed, static_argnums=(3, 4, 5, 6))
    fits = windowed(*args, s.spec, (24, 16), 10, s.n_substeps)
    self.assertFalse(np.asarray(fits[4]).any())
    np.testing.assert_allclose(fits[1], whole[1], atol=WINDOW_TOLERANCE_M,
                               rtol=0)
    np.testing.assert_allclose(fits[2], whole[2], atol=1e-5, rtol=0)
    np.testing.assert_array_equal(fits[3], whole[3])
    # The sand spans 5 x 4 cells: its stencils need 8 x 7 nodes.
    small = windowed(*args, s.spec, (7, 6), 10, s.n_substeps)
    self.assertTrue(np.asarray(small[4])[0])

  def test_boundary_capacity_is_the_most_entries_any_window_holds(self):
    s = mpm.setup(_wide(obstacles=[{"shape": "rectangle", "x": 0.4,
                                     "width": 0.06, "height": 0.05}]))
    index = np.asarray(s.field.index)
    rows, cols = np.divmod(index[index > 0], s.spec.shape[1])
    for size in [(8, 8), (16, 8), (24, 16), (52, 30)]:
      brute = max(
          int(np.sum((rows >= a) & (rows < a + size[0]) &
                     (cols >= b) & (cols < b + size[1])))
          for a in range(s.spec.shape[0] - size[0] + 1)
          for b in range(s.spec.shape[1] - size[1] + 1))
      self.assertEqual(window.boundary_count(index, s.spec, size), brute)
      # Rounded up to a power of two, so that scenes share programs.
      capacity = window.boundary_capacity(index, s.spec, size)
      self.assertEqual(capacity, min(len(index), max(
          window.CAPACITY_MIN, 2**int(np.ceil(np.log2(brute))))))
    self.assertEqual(window.boundary_count(index, s.spec, (52, 30)),
                     len(rows))
    # A batch of fields: the largest over its scenes.
    self.assertEqual(window.boundary_count(
        np.stack([index, np.zeros_like(index)]), s.spec, (16, 8)),
                     window.boundary_count(index, s.spec, (16, 8)))

  def test_a_windowed_field_on_its_capacity_sets_every_node_as_all_entries(
      self):
    s = mpm.setup(_wide(obstacles=[{"shape": "semicircle", "x": 0.3,
                                     "radius": 0.04}]))
    size = (16, 16)
    capacity = window.boundary_capacity(s.field.index, s.spec, size)
    self.assertLess(capacity, np.sum(np.asarray(s.field.index) > 0) / 2)
    grid_v = jax.random.normal(jax.random.key(0), (size[0] * size[1] + 1, 2))
    for at in [(0, 0), (10, 0), (14, 5), (36, 14)]:
      at = jnp.asarray(at, jnp.int32)
      every = boundary.window(s.field, s.spec, size, at)
      some = boundary.window(s.field, s.spec, size, at, capacity)
      self.assertEqual(some.index.shape, (capacity,))
      apply = lambda f: boundary.apply(f, grid_v, 0.4, 0.2)[:-1]
      np.testing.assert_array_equal(apply(some), apply(every))
      # Something was set: the window holds boundary nodes that act.
      self.assertGreater(np.abs(apply(every) - grid_v[:-1]).max(), 0.0)


class RestTest(absltest.TestCase):
  """``rest_speed``: a run stops stepping once its sand rests."""

  def test_a_resting_deposit_stops_stepping_and_keeps_every_frame(self):
    scene = _scene("settles", num_frames=121)   # settles in ~0.3 s of 1.2
    full = mpm.simulate(scene, chunk_frames=10)
    # At rest: no particle moved more than 2 mm in the last 0.1 s.
    rest = mpm.simulate(scene, chunk_frames=10, rest_speed=0.02,
                        rest_frames=10)
    self.assertIsNone(full.rest_frame)
    self.assertIsNotNone(rest.rest_frame)
    self.assertLess(rest.rest_frame, 80)
    self.assertEqual(rest.positions.shape, full.positions.shape)
    stepped = rest.rest_frame + 1
    # The frames stepped are the full run's; the rest repeat the last one.
    np.testing.assert_array_equal(rest.positions[:stepped],
                                  full.positions[:stepped])
    np.testing.assert_array_equal(
        rest.positions[stepped:],
        np.broadcast_to(rest.positions[stepped - 1],
                        rest.positions[stepped:].shape))
    window = full.positions[rest.rest_frame - 10:rest.rest_frame + 1]
    self.assertLess(np.abs(window[-1] - window[0]).max(), 2e-3)
    # What the skipped frames would have moved: no more than the rest speed
    # for their duration (this soft, coarse sand still creeps: ~6 mm).
    skipped_s = (scene.num_frames - 1 - rest.rest_frame) * scene.frame_dt
    self.assertLess(np.abs(rest.positions[-1] - full.positions[-1]).max(),
                    0.02 * skipped_s)

  def test_sand_that_keeps_moving_is_stepped_to_the_end(self):
    scene = _scene("moving", num_frames=21)
    self.assertIsNone(mpm.simulate(scene, chunk_frames=10, rest_speed=1e-6,
                                   rest_frames=5).rest_frame)


class SimulationErrorTest(absltest.TestCase):

  def test_too_few_substeps_for_stiff_sand(self):
    # E = 1e8 Pa needs ~100 substeps per frame here; force 2.
    scene = _scene("too_stiff", material={
        "density": 1500.0, "youngs_modulus": 1e8, "poisson_ratio": 0.3,
        "friction_angle_deg": 35.0}, num_frames=11)
    s = mpm.setup(scene)
    self.assertGreater(s.n_substeps, 50)
    n_substeps = 2
    s = dataclasses.replace(s, n_substeps=n_substeps, params=s.params.replace(
        dt=jnp.float32(scene.frame_dt / n_substeps)))
    with self.assertRaises(mpm.SimulationError) as cm:
      mpm.simulate_setups([s], chunk_frames=4)
    e = cm.exception
    self.assertEqual(e.scene_name, "too_stiff")
    self.assertIn("'too_stiff'", str(e))
    self.assertIn(f"frame {e.frame}", str(e))
    # The frame is the first one that went non-finite or too fast.
    _, _, speed, finite = jax.jit(solver.rollout, static_argnums=(3, 4, 5))(
        s.state, s.params, s.field, s.spec, scene.num_frames - 1, n_substeps)
    bad = ~np.asarray(finite) | ~(np.asarray(speed) <= s.max_speed)
    self.assertTrue(np.any(bad))
    self.assertEqual(e.frame, 1 + int(np.argmax(bad)))

  def test_check_frames_names_the_scene_and_first_bad_frame(self):
    finite = np.array([True, True, False, False])
    speed = np.array([0.5, 0.9, np.nan, np.nan], np.float32)
    with self.assertRaisesRegex(mpm.SimulationError,
                                "'s', frame 12: positions are not finite"
                                ) as cm:
      mpm.check_frames("s", 10, finite, speed, 1.0)
    self.assertEqual((cm.exception.scene_name, cm.exception.frame), ("s", 12))
    too_fast = np.array([0.5, 1.5, 2.0], np.float32)
    with self.assertRaisesRegex(mpm.SimulationError,
                                r"frame 2: particle speed 1.500.*CFL") as cm:
      mpm.check_frames("s", 1, np.ones(3, bool), too_fast, 1.0)
    self.assertEqual(cm.exception.frame, 2)
    mpm.check_frames("s", 1, np.ones(2, bool), np.array([0.5, 1.0]), 1.0)

  def _launched(self, speed):
    """A setup whose sand starts at ``speed`` (m/s) along the floor."""
    s = mpm.setup(_scene("launched", num_frames=9))
    v = s.state.v.at[:, 0].set(speed)
    return dataclasses.replace(s, state=s.state.replace(v=v))

  def test_a_particle_past_the_bound_raises_the_substeps_and_goes_on(self):
    s = self._launched(0.0)
    s = self._launched(1.5 * s.max_speed)
    # The whole grid: windows sized for either count would differ by ulps.
    result = mpm.simulate_setups([s], chunk_frames=4, grid_window=False)
    self.assertEqual(result[0].n_substeps,
                     2 * s.n_substeps)
    self.assertGreater(result[0].max_speed.max(), s.max_speed)
    # The same as a run with twice the substeps from the start.
    twice = dataclasses.replace(
        s, n_substeps=2 * s.n_substeps,
        max_speed=mpm.simulation.speed_allowed(s.scene, 2 * s.n_substeps),
        params=s.params.replace(dt=jnp.float32(s.scene.frame_dt /
                                               (2 * s.n_substeps))))
    np.testing.assert_array_equal(
        result[0].positions,
        mpm.simulate_setups([twice], chunk_frames=4,
                            grid_window=False)[0].positions)

  def test_past_the_top_of_the_ladder_it_is_an_error(self):
    s = self._launched(0.0)
    top = mpm.simulation.speed_allowed(
        s.scene, s.n_substeps * mpm.simulation.SUBSTEP_LADDER[-1])
    with self.assertRaisesRegex(mpm.SimulationError, r"'launched', frame 1: "
                                "particle speed .* exceeds"):
      mpm.simulate_setups([self._launched(1.5 * top)], chunk_frames=4)

  def test_stable_scene_does_not_raise(self):
    result = mpm.simulate(_scene("fine"))
    self.assertTrue(np.all(result.max_speed <= mpm.setup(
        _scene("fine")).max_speed))


if __name__ == "__main__":
  absltest.main()
