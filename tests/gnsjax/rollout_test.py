"""Tests for `gnsjax.rollout`."""

import dataclasses
import functools
import time
from unittest import mock

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mpm
from experiments.studies import settings
from gnsjax import data
from gnsjax import features
from gnsjax import graph
from gnsjax import metrics
from gnsjax import models
from gnsjax import rollout
from gnsjax import run as run_lib
from gnsjax import simulator
from mpm import geometry
from tests.gnsjax import fixtures

C = 6


@functools.lru_cache(maxsize=None)
def tiny_model():
  """(predictor, params) of an untrained two-step model (random weights)."""
  model = models.EncodeProcessDecode(latent_size=16, hidden_layers=1,
                                     num_message_passing_steps=2,
                                     type_embedding_size=4)
  params = models.init_params(model, jax.random.key(0),
                              features.num_node_features(C))
  return simulator.ModelPredictor(model), params


def spread(n: int, spec: graph.GraphSpec) -> np.ndarray:
  """[n, 2] positions on a lattice wider than the radius (self-edges only):
  a list allocated for them overflows at the first real update."""
  bounds = np.asarray(spec.bounds)
  columns = int((bounds[0, 1] - bounds[0, 0]) // (1.05 * spec.radius))
  cells = np.stack(np.divmod(np.arange(n), columns), -1)
  positions = bounds[:, 0] + 1.05 * spec.radius * cells[:, ::-1]
  assert np.all(positions <= bounds[:, 1]), "too many nodes to spread"
  return positions.astype(np.float32)


@dataclasses.dataclass(frozen=True)
class OraclePredictor:
  """Returns the true normalised acceleration: finds the stored frame that
  matches the last input frame and aims at the one after it."""

  def __call__(self, params, g, context, radius):
    del radius
    frames = params                                       # [T, N, 2]
    dist = jnp.sum((frames[:-1] - g.positions[-1][None])**2, axis=(1, 2))
    k = jnp.argmin(dist)
    return features.target_acceleration(g.positions, frames[k + 1],
                                        context.stats)


def with_boundary(t, positions):
  """[T, N + Nb, 2]: the trajectory's sand frames, then its boundary."""
  return np.concatenate(
      [positions, np.broadcast_to(t.boundary_positions[None],
                                  (len(positions),) +
                                  t.boundary_positions.shape)], 1)


class RolloutTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.data = fixtures.tiny_dataset()
    cls.config = fixtures.tiny_config()
    cls.problem = run_lib.load_problem(cls.data, cls.config)
    cls.trajectory = next(data.trajectories(data.split_path(cls.data, "test")))

  def _oracle(self, k, c, project):
    t = self.trajectory
    scene = rollout.trajectory_nodes(t, c, k,
                                     sdf_spacing=self.problem.sdf_spacing)
    frames = rollout.predicted_frame_indices(len(t.positions), c, k)
    problem = dataclasses.replace(self.problem, stats=data.load_stats(
        data.split_path(self.data, "train"), k))
    stored = jnp.asarray(with_boundary(t, t.positions[::k]))
    out = rollout.rollout(OraclePredictor(), stored, scene, len(frames),
                          problem.context, problem.spec, project=project,
                          chunk=4)
    return t, scene, frames, out

  def test_oracle_reproduces_the_stored_trajectory(self):
    # With the constraint on: the MPM's sand stays out of the solids, so the
    # constraint leaves it alone.
    t, scene, frames, out = self._oracle(1, C, project=True)
    moving = scene.moving
    steps = len(t.positions) - C
    np.testing.assert_array_equal(frames, np.arange(C, len(t.positions)))
    self.assertEqual(out.positions.shape, (steps,) + scene.window.shape[1:])
    self.assertEqual(out.pushed.shape, (steps,))
    self.assertEqual(out.depth.shape, (steps,))
    np.testing.assert_allclose(out.positions[:, moving], t.positions[C:],
                               atol=2e-6)
    np.testing.assert_array_equal(out.pushed, 0)
    # Boundary particles never move.
    np.testing.assert_array_equal(
        out.positions[:, ~moving],
        np.broadcast_to(scene.window[-1, ~moving],
                        out.positions[:, ~moving].shape))

  def test_oracle_at_a_frame_stride(self):
    # Stride 3 from 3 input frames: inputs 0, 3, 6; predicted 9, 12, 15.
    t, scene, frames, out = self._oracle(3, 3, project=False)
    np.testing.assert_array_equal(rollout.input_frame_indices(3, 3),
                                  [0, 3, 6])
    np.testing.assert_array_equal(frames, [9, 12, 15])
    np.testing.assert_array_equal(scene.window[:, scene.moving],
                                  t.positions[[0, 3, 6]])
    np.testing.assert_allclose(out.positions[:, scene.moving],
                               t.positions[frames], atol=2e-6)

  def test_trajectory_nodes(self):
    t = self.trajectory
    scene = rollout.trajectory_nodes(t, C, 2, sdf_spacing=0.02)
    n, nb = t.positions.shape[1], len(t.boundary_positions)
    self.assertEqual(scene.window.shape, (C, n + nb, 2))
    np.testing.assert_array_equal(scene.window[:, :n], t.positions[:2 * C:2])
    np.testing.assert_array_equal(scene.moving, np.arange(n + nb) < n)
    np.testing.assert_array_equal(scene.types[n:], t.boundary_type)
    np.testing.assert_array_equal(
        scene.solids.values,
        geometry.scene_sdf_grid(t.scene, 0.02).values)
    later = rollout.trajectory_nodes(t, C, 2, sdf_spacing=0.02, start=3)
    np.testing.assert_array_equal(later.window[:, :n],
                                  t.positions[3:3 + 2 * C:2])
    alone = rollout.trajectory_nodes(t, C, boundary=False)
    self.assertEqual(alone.window.shape, (C, n, 2))
    self.assertTrue(np.all(alone.moving))
    self.assertEqual(alone.solids.spacing, 0.005)

  def test_rollout_trajectory_is_the_sand_of_a_rollout(self):
    t = self.trajectory
    predictor, params = tiny_model()
    out = rollout.rollout_trajectory(predictor.model, params, t,
                                     self.problem, n_steps=4)
    scene = rollout.trajectory_nodes(t, C, 1, self.problem.boundary_particles,
                                     self.problem.sdf_spacing)
    whole = rollout.rollout(predictor, params, scene, 4,
                            self.problem.context, self.problem.spec)
    self.assertEqual(out.positions.shape, (4,) + t.positions.shape[1:])
    np.testing.assert_allclose(out.positions,
                               whole.positions[:, scene.moving], atol=1e-6)
    np.testing.assert_array_equal(out.pushed, whole.pushed)

  def test_reallocation_mid_scan_equals_ample_capacity(self):
    t = self.trajectory
    scene = rollout.trajectory_nodes(t, C,
                                     sdf_spacing=self.problem.sdf_spacing)
    predictor, params = tiny_model()
    spec = self.problem.spec
    n = scene.window.shape[1]
    small = graph.allocate(spec, jnp.asarray(spread(n, spec)))
    # Ample: 64 more edges per node and slots per cell than the start needs
    # (never reallocated, checked below; 4096 padded it to N x 4096 edges).
    ample = graph.allocate(spec, jnp.asarray(scene.window[-1]),
                           extra_capacity=64)
    steps = 9
    reallocations, ample_reallocations = [], []
    a = rollout.rollout(predictor, params, scene, steps, self.problem.context,
                        spec, chunk=4, nbrs=small,
                        on_reallocate=reallocations.append)
    b = rollout.rollout(predictor, params, scene, steps, self.problem.context,
                        spec, chunk=4, nbrs=ample,
                        on_reallocate=ample_reallocations.append)
    self.assertNotEmpty(reallocations)
    self.assertEmpty(ample_reallocations)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-6)
    np.testing.assert_array_equal(a.pushed, b.pushed)
    self.assertTrue(np.all(np.isfinite(a.positions)))

  def test_bad_scene_raises(self):
    scene = rollout.trajectory_nodes(self.trajectory, C,
                                     sdf_spacing=self.problem.sdf_spacing)
    predictor, params = tiny_model()
    run = lambda sc: rollout.rollout(predictor, params, sc, 1,
                                     self.problem.context, self.problem.spec)
    with self.assertRaisesRegex(ValueError, r"rollout: window must be "
                                r"\[C, N, 2\]"):
      run(scene._replace(window=scene.window[..., 0]))
    with self.assertRaisesRegex(ValueError, "rollout: moving must be"):
      run(scene._replace(moving=scene.moving[:-1]))
    with self.assertRaisesRegex(ValueError, r"solids.values must be "
                                r"\[Gx, Gy, 3\]"):
      run(scene._replace(solids=scene.solids.replace(
          values=scene.solids.values[..., :2])))


def contact_scene(obstacles, spacing=0.02):
  """(scene, sand [N, 2]): the default domain and ramp with ``obstacles``,
  and a block of sand just above them (half a spacing clear)."""
  scene = mpm.Scene.from_dict({
      "name": "contact", "obstacles": obstacles,
      "granular": {"box": [0.7, 0.05, 1.1, 0.3], "spacing": spacing,
                   "num_particles": None}})
  return scene, mpm.granular_particles(scene)


def falling_nodes(scene, sand, sdf_spacing, speed=2e-3):
  """The scene's start for a rollout: sand falling at ``speed`` (m/step)
  onto the solids, then its boundary particles."""
  v = np.array([0.0, -speed], np.float32)
  window = sand[None] + (np.arange(C) - C + 1)[:, None, None] * v
  boundary, types = mpm.boundary_particles(scene)
  nodes = np.concatenate(
      [window, np.broadcast_to(boundary[None], (C,) + boundary.shape)], 1)
  return rollout.SceneNodes(
      nodes.astype(np.float32),
      np.concatenate([np.full(len(sand), mpm.SAND_TYPE), types]),
      np.arange(len(nodes[0])) < len(sand),
      data.solids_of(scene, sdf_spacing))


class SolidConstraintTest(absltest.TestCase):
  """Untrained rollouts of sand falling onto the solids, with and without
  ``project``."""

  STEPS = 20

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.problem = run_lib.load_problem(fixtures.tiny_dataset(),
                                     fixtures.tiny_config())
    # A grid fine enough for the semicircle's curvature: bilinear
    # interpolation is within h^2 / (8 r) = 1.6e-5 m of its distance.
    cls.scene, sand = contact_scene(
        [{"shape": "semicircle", "x": 0.85, "radius": 0.05}])
    cls.nodes = falling_nodes(cls.scene, sand, 0.0025)
    predictor, params = tiny_model()
    run = lambda project: rollout.rollout(
        predictor, params, cls.nodes, cls.STEPS, cls.problem.context,
        cls.problem.spec, project=project, chunk=10)
    cls.constrained, cls.free = run(True), run(False)

  def _sand(self, out):
    return out.positions[:, self.nodes.moving]

  def test_no_sand_inside_solids_with_the_constraint(self):
    inside = metrics.inside_solids(self._sand(self.constrained), self.scene,
                                   tolerance=1e-4)
    self.assertEqual(inside.shape, (self.STEPS,))
    np.testing.assert_array_equal(inside, 0.0)
    self.assertEqual(np.max(metrics.outside_domain(
        self._sand(self.constrained), self.scene, tolerance=1e-4)), 0.0)
    # The constraint had work to do: without it, sand goes in.
    self.assertGreater(np.max(metrics.inside_solids(
        self._sand(self.free), self.scene, tolerance=1e-4)), 0.02)
    self.assertGreater(self.constrained.pushed.sum(), 20)

  def test_pushed_counts_are_consistent_with_the_positions(self):
    c, f = self.constrained, self.free
    n_sand = int(self.nodes.moving.sum())
    np.testing.assert_array_equal(f.pushed, 0)
    np.testing.assert_array_equal(f.depth, 0.0)
    self.assertTrue(np.all((c.pushed >= 0) & (c.pushed <= n_sand)))
    np.testing.assert_array_equal(c.depth > 0, c.pushed > 0)
    # Until the first push, both rollouts are the same; at it, the free
    # rollout's sand inside the grid is what the constraint counts and
    # moves.
    first = int(np.argmax(c.pushed > 0))
    self.assertGreater(first, 0)
    np.testing.assert_array_equal(c.positions[:first], f.positions[:first])
    phi, normal = map(np.asarray, geometry.sample_sdf(
        self.nodes.solids, jnp.asarray(f.positions[first])))
    inside = self.nodes.moving & (phi < 0)
    self.assertEqual(c.pushed[first], inside.sum())
    np.testing.assert_allclose(c.depth[first], -phi[inside].min(), atol=1e-7)
    np.testing.assert_allclose(
        c.positions[first, inside],
        f.positions[first, inside] - phi[inside, None] * normal[inside],
        atol=1e-6)
    np.testing.assert_array_equal(c.positions[first, ~inside],
                                  f.positions[first, ~inside])
    # Static nodes never move.
    static = ~self.nodes.moving
    np.testing.assert_array_equal(
        c.positions[:, static],
        np.broadcast_to(self.nodes.window[-1, static],
                        c.positions[:, static].shape))

  def test_no_sand_inside_polygons(self):
    # Sand falling onto a rectangle and a triangle, at the run's SDF spacing.
    # Measured with the exact distance, sand may stay inside a convex corner
    # by the grid's interpolation error there (at most h / sqrt(2), h the
    # SDF spacing; 3.2 mm here with h = 10 mm), never deeper: the
    # evaluation's threshold, half a particle spacing, is above it whenever
    # h < 0.7 spacing (the default h = R / 6 is).
    scene, sand = contact_scene([
        {"shape": "rectangle", "x": 0.8, "width": 0.06, "height": 0.05},
        {"shape": "triangle", "x": 1.0, "base": 0.08, "height": 0.06}])
    nodes = falling_nodes(scene, sand, self.problem.sdf_spacing)
    predictor, params = tiny_model()
    out = rollout.rollout(predictor, params, nodes, 30, self.problem.context,
                          self.problem.spec, chunk=10)
    np.testing.assert_array_equal(metrics.inside_solids(
        out.positions[:, nodes.moving], scene,
        tolerance=self.problem.sdf_spacing / np.sqrt(2)), 0.0)


class RolloutBatchTest(absltest.TestCase):
  """``rollout_batch`` on three scenes of different node counts."""

  STEPS = 7

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.data = fixtures.tiny_dataset()
    cls.problem = run_lib.load_problem(cls.data, fixtures.tiny_config())
    t0, t1 = list(data.trajectories(data.split_path(cls.data, "test")))[:2]
    spacing = cls.problem.sdf_spacing
    cls.scenes = [rollout.trajectory_nodes(t0, C, sdf_spacing=spacing),
                  rollout.trajectory_nodes(t1, C, sdf_spacing=spacing)]
    # The first scene without its last 40 boundary particles.
    w, ty, m, so = cls.scenes[0]
    cls.scenes.append(rollout.SceneNodes(w[:, :-40], ty[:-40], m[:-40], so))
    cls.predictor, cls.params = tiny_model()
    cls.reallocations = []
    cls.batched = cls._rollout_batch(cls.problem.spec,
                                     on_reallocate=cls.reallocations.append)

  @classmethod
  def _rollout_batch(cls, spec, scenes=None, **kwargs):
    return rollout.rollout_batch(cls.predictor, cls.params,
                                 cls.scenes if scenes is None else scenes,
                                 cls.STEPS, cls.problem.context, spec,
                                 chunk=4, **kwargs)

  def test_equals_separate_rollouts(self):
    sizes = [len(sc.types) for sc in self.scenes]
    self.assertLen(set(sizes), 3)
    self.assertLen(self.batched, 3)
    for sc, pred in zip(self.scenes, self.batched):
      w, m = sc.window, sc.moving
      self.assertEqual(pred.positions.shape, (self.STEPS,) + w.shape[1:])
      self.assertEqual(pred.positions.dtype, np.float32)
      alone = rollout.rollout(self.predictor, self.params, sc, self.STEPS,
                              self.problem.context, self.problem.spec,
                              chunk=4)
      np.testing.assert_allclose(pred.positions, alone.positions, rtol=0,
                                 atol=1e-5)
      np.testing.assert_array_equal(pred.pushed, alone.pushed)
      np.testing.assert_allclose(pred.depth, alone.depth, atol=1e-6)
      # The model moves the sand (the comparison is not vacuous).
      self.assertGreater(np.max(np.abs(pred.positions[-1, m] - w[-1, m])),
                         1e-6)

  def test_buckets_group_by_size_and_keep_the_order(self):
    sizes = [len(sc.types) for sc in self.scenes]
    # A ratio that separates the smallest scene from the other two.
    ratio = (sorted(sizes)[1] / sorted(sizes)[0] + 1) / 2
    self.assertGreaterEqual(
        len(mpm.simulation.size_buckets(sizes, ratio)), 2)
    buckets = rollout.rollout_buckets(
        self.predictor, self.params, self.scenes, self.STEPS,
        self.problem.context, self.problem.spec, bucket_ratio=ratio,
        max_batch=3, chunk=4)
    self.assertLen(buckets, 3)
    for pred, bucket in zip(self.batched, buckets):
      self.assertEqual(bucket.positions.shape, pred.positions.shape)
      np.testing.assert_allclose(bucket.positions, pred.positions, rtol=0,
                                 atol=1e-5)

  def test_max_batch_splits_a_bucket(self):
    # One bucket of all three scenes, run as batches of at most two, and by
    # default on the CPU one at a time: the same results, in order.
    sizes = [len(sc.types) for sc in self.scenes]
    ratio = max(sizes) / min(sizes)
    self.assertLen(mpm.simulation.size_buckets(sizes, ratio), 1)
    self.assertEqual(rollout.default_max_batch(), 1)   # the suite's CPU
    calls = []
    real = rollout.rollout_batch

    def counted(predictor, params, scenes, *args, **kwargs):
      calls.append(len(scenes))
      return real(predictor, params, scenes, *args, **kwargs)

    with mock.patch.object(rollout, "rollout_batch", counted):
      for max_batch, expected in ((2, [2, 1]), (None, [1, 1, 1])):
        calls.clear()
        out = rollout.rollout_buckets(
            self.predictor, self.params, self.scenes, self.STEPS,
            self.problem.context, self.problem.spec, bucket_ratio=ratio,
            max_batch=max_batch, chunk=4)
        self.assertEqual(calls, expected)
        for pred, got in zip(self.batched, out):
          np.testing.assert_allclose(got.positions, pred.positions, rtol=0,
                                     atol=1e-5)
    with self.assertRaisesRegex(ValueError, "max_batch = 0"):
      rollout.rollout_buckets(self.predictor, self.params, self.scenes,
                              self.STEPS, self.problem.context,
                              self.problem.spec, max_batch=0)

  def test_reallocation_equals_ample_capacity(self):
    # No headroom: reallocated lists overflow again as soon as any scene gains
    # an edge, mid-chunk; the first list (self-edges only) at step 0.
    spec = dataclasses.replace(self.problem.spec, capacity_multiplier=1.0)
    n = max(len(sc.types) for sc in self.scenes)
    small = graph.allocate_batch(
        spec, jnp.asarray(np.stack([spread(n, spec)] * len(self.scenes))))
    reallocations = []
    tight = self._rollout_batch(spec, nbrs=small,
                                on_reallocate=reallocations.append)
    self.assertEqual(reallocations[0], 0)
    self.assertTrue(any(k % 4 for k in reallocations), reallocations)
    # The reference never reallocated: its capacity sufficed throughout.
    self.assertEmpty(self.reallocations)
    for a, b in zip(tight, self.batched):
      np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-6)
      self.assertTrue(np.all(np.isfinite(a.positions)))

  def test_static_nodes_stay_bit_identical(self):
    for sc, pred in zip(self.scenes, self.batched):
      w, m = sc.window, sc.moving
      np.testing.assert_array_equal(
          pred.positions[:, ~m],
          np.broadcast_to(w[-1, ~m], pred.positions[:, ~m].shape))

  def test_bad_input_raises(self):
    scenes = self.scenes
    run = lambda sc: rollout.rollout_batch(
        self.predictor, self.params, sc, 2, self.problem.context,
        self.problem.spec)
    with self.assertRaisesRegex(ValueError, r"scene 1: window must be "
                                r"\[C, N, 2\].*\(6, \d+\)"):
      run([scenes[0], scenes[1]._replace(window=scenes[1].window[..., 0]),
           scenes[2]])
    with self.assertRaisesRegex(ValueError, "scene 2: types must be"):
      run(scenes[:2] + [scenes[2]._replace(types=scenes[2].types[:-1])])
    with self.assertRaisesRegex(ValueError, "scene 1 has 5 input frames"):
      run([scenes[0], scenes[1]._replace(window=scenes[1].window[1:]),
           scenes[2]])
    coarse = scenes[1]._replace(solids=data.solids_of(
        self.trajectory_scene(1), 2 * self.problem.sdf_spacing))
    with self.assertRaisesRegex(ValueError, "scene 1's SDF grid is"):
      run([scenes[0], coarse])
    with self.assertRaisesRegex(ValueError, "no scenes"):
      run([])

  def trajectory_scene(self, index):
    return list(data.trajectories(data.split_path(self.data,
                                                  "test")))[index].scene


def resting_scene(num_particles: int, x: float, radius: float,
                  sdf_spacing: float):
  """(scene, SceneNodes): the small config's sand (spacing 0.01 m) at rest
  above a semicircle obstacle, then its boundary."""
  scene = mpm.Scene.from_dict({
      "name": "resting", "granular": {"box": [1.25, 0.5, 1.46, 1.19],
                                      "spacing": 0.01,
                                      "num_particles": num_particles},
      "obstacles": [{"shape": "semicircle", "x": x, "radius": radius}]})
  sand = mpm.granular_particles(scene)
  boundary, boundary_types = mpm.boundary_particles(scene)
  nodes = np.concatenate([sand, boundary])
  window = np.broadcast_to(nodes[None], (C,) + nodes.shape)
  types = np.concatenate(
      [np.full(len(sand), mpm.SAND_TYPE, np.int32), boundary_types])
  moving = np.arange(len(types)) < len(sand)
  return scene, rollout.SceneNodes(window, types, moving,
                                   data.solids_of(scene, sdf_spacing))


@pytest.mark.slow  # ~1 min on 2 CPU cores: 2000 + 2 x 600 model steps.
class PretrainedStabilityTest(absltest.TestCase):
  """Long rollouts of the shipped small model stay finite and in the domain.

  The sand starts at rest, as the MPM's does. (The model keeps a resting heap
  nearly still, so this guards against blow-ups, not against drift.)
  """

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    # From the checkpoint alone (its stored config and problem).
    run = run_lib.load_run(settings.PRETRAINED)
    cls.problem, cls.params = run.problem, run.params
    cls.predictor = simulator.ModelPredictor(run.model)
    cls.scenes = [resting_scene(200, 0.9, 0.04, cls.problem.sdf_spacing),
                  resting_scene(180, 0.7, 0.03, cls.problem.sdf_spacing)]
    domain = cls.scenes[0][0].domain
    cls.bounds = np.array([[0.0, domain.width], [0.0, domain.height]])

  def _assert_in_domain(self, positions):
    self.assertTrue(np.all(np.isfinite(positions)))
    margin = 3 * self.problem.radius
    out = np.any((positions < self.bounds[:, 0] - margin) |
                 (positions > self.bounds[:, 1] + margin), axis=-1)
    steps, nodes = np.nonzero(out)
    self.assertFalse(out.any(), f"{len(set(nodes))} nodes leave the domain, "
                     f"first at step {steps.min() if out.any() else None}")

  def test_2000_steps_stay_finite_in_the_domain(self):
    _, scene = self.scenes[0]
    start = time.perf_counter()
    pred = rollout.rollout(self.predictor, self.params, scene, 2000,
                           self.problem.context, self.problem.spec)
    print(f"2000-step rollout: {time.perf_counter() - start:.1f} s")
    self.assertEqual(pred.positions.shape, (2000,) + scene.window.shape[1:])
    self._assert_in_domain(pred.positions)

  def test_600_batched_steps_stay_finite_in_the_domain(self):
    scenes = [sc for _, sc in self.scenes]
    self.assertNotEqual(len(scenes[0].types), len(scenes[1].types))
    start = time.perf_counter()
    preds = rollout.rollout_batch(self.predictor, self.params, scenes, 600,
                                  self.problem.context, self.problem.spec)
    print(f"600-step batched rollout: {time.perf_counter() - start:.1f} s")
    for sc, pred in zip(scenes, preds):
      self.assertEqual(pred.positions.shape, (600,) + sc.window.shape[1:])
      self._assert_in_domain(pred.positions)


if __name__ == "__main__":
  absltest.main()
