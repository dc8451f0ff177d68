"""Tests for `gnsjax.rollout`."""

import dataclasses
import time

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mpm
from experiments import tasks
from gnsjax import data
from gnsjax import evaluate
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import rollout
from gnsjax import simulator
from gnsjax import train
from tests.gnsjax import fixtures

C = 6


def tiny_model(types: np.ndarray):
  """(predictor, params) of an untrained two-step model (random weights)."""
  model = models.EncodeProcessDecode(latent_size=16, hidden_layers=1,
                                     num_message_passing_steps=2,
                                     type_embedding_size=4)
  node_f = jnp.zeros((len(types), 2 * (C - 1) + 4))
  params = model.init(jax.random.key(0), node_f, jnp.asarray(types),
                      jnp.zeros((4, 3)), jnp.zeros(4, jnp.int32),
                      jnp.zeros(4, jnp.int32))
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

  def __call__(self, params, positions, particle_type, senders, receivers,
               context, radius):
    del particle_type, senders, receivers, radius
    frames = params                                       # [T, N, 2]
    dist = jnp.sum((frames[:-1] - positions[-1][None])**2, axis=(1, 2))
    k = jnp.argmin(dist)
    return features.target_acceleration(positions, frames[k + 1],
                                        context.stats)


class RolloutTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.data = fixtures.tiny_dataset()
    cls.config = fixtures.tiny_config()
    cls.problem = train.load_problem(cls.data, cls.config)
    cls.trajectory = next(data.trajectories(data.split_path(cls.data, "test")))

  def test_oracle_reproduces_the_stored_trajectory(self):
    t = self.trajectory
    window, types, moving = rollout.trajectory_nodes(t, C)
    frames = np.concatenate(
        [t.positions, np.broadcast_to(t.boundary_positions[None],
                                      (len(t.positions),) +
                                      t.boundary_positions.shape)], 1)
    steps = len(t.positions) - C
    pred = rollout.rollout(OraclePredictor(), jnp.asarray(frames), window,
                           types, moving, steps, self.problem.context,
                           self.problem.spec, chunk=4)
    self.assertEqual(pred.shape, (steps,) + window.shape[1:])
    np.testing.assert_allclose(pred[:, moving], t.positions[C:], atol=2e-6)
    # Boundary particles never move.
    np.testing.assert_array_equal(pred[:, ~moving],
                                  np.broadcast_to(window[-1, ~moving],
                                                  pred[:, ~moving].shape))

  def test_reallocation_mid_scan_equals_ample_capacity(self):
    t = self.trajectory
    window, types, moving = rollout.trajectory_nodes(t, C)
    predictor, params = tiny_model(types)
    spec = self.problem.spec
    small = graph.allocate(spec, jnp.asarray(spread(window.shape[1], spec)))
    ample = graph.allocate(spec, jnp.asarray(window[-1]), extra_capacity=4096)
    steps = 9
    reallocations = []
    a = rollout.rollout(predictor, params, window, types, moving, steps,
                        self.problem.context, spec, chunk=4, nbrs=small,
                        on_reallocate=reallocations.append)
    b = rollout.rollout(predictor, params, window, types, moving, steps,
                        self.problem.context, spec, chunk=4, nbrs=ample)
    self.assertNotEmpty(reallocations)
    np.testing.assert_allclose(a, b, atol=1e-6)
    self.assertTrue(np.all(np.isfinite(a)))


class RolloutBatchTest(absltest.TestCase):
  """``rollout_batch`` on three scenes of different node counts."""

  STEPS = 7

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.data = fixtures.tiny_dataset()
    cls.problem = train.load_problem(cls.data, fixtures.tiny_config())
    t0, t1 = list(data.trajectories(data.split_path(cls.data, "test")))[:2]
    cls.scenes = [rollout.trajectory_nodes(t0, C),
                  rollout.trajectory_nodes(t1, C)]
    # The first scene without its last 40 boundary particles.
    w, ty, m = cls.scenes[0]
    cls.scenes.append((w[:, :-40], ty[:-40], m[:-40]))
    cls.predictor, cls.params = tiny_model(cls.scenes[0][1])
    cls.reallocations = []
    cls.batched = cls._rollout_batch(cls.problem.spec,
                                     on_reallocate=cls.reallocations.append)

  @classmethod
  def _rollout_batch(cls, spec, **kwargs):
    windows, types, moving = map(list, zip(*cls.scenes))
    return rollout.rollout_batch(cls.predictor, cls.params, windows, types,
                                 moving, cls.STEPS, cls.problem.context, spec,
                                 chunk=4, **kwargs)

  def test_equals_separate_rollouts(self):
    sizes = [len(ty) for _, ty, _ in self.scenes]
    self.assertLen(set(sizes), 3)
    self.assertLen(self.batched, 3)
    for (w, ty, m), pred in zip(self.scenes, self.batched):
      self.assertEqual(pred.shape, (self.STEPS,) + w.shape[1:])
      self.assertEqual(pred.dtype, np.float32)
      alone = rollout.rollout(self.predictor, self.params, w, ty, m,
                              self.STEPS, self.problem.context,
                              self.problem.spec, chunk=4)
      np.testing.assert_allclose(pred, alone, rtol=0, atol=1e-5)
      # The model moves the sand (the comparison is not vacuous).
      self.assertGreater(np.max(np.abs(pred[-1, m] - w[-1, m])), 1e-6)

  def test_reallocation_equals_ample_capacity(self):
    # No headroom: reallocated lists overflow again as soon as any scene gains
    # an edge, mid-chunk; the first list (self-edges only) at step 0.
    spec = dataclasses.replace(self.problem.spec, capacity_multiplier=1.0)
    n = max(len(ty) for _, ty, _ in self.scenes)
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
      np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
      self.assertTrue(np.all(np.isfinite(a)))

  def test_static_nodes_stay_bit_identical(self):
    for (w, _, m), pred in zip(self.scenes, self.batched):
      np.testing.assert_array_equal(
          pred[:, ~m], np.broadcast_to(w[-1, ~m], pred[:, ~m].shape))

  def test_bad_input_raises(self):
    windows, types, moving = map(list, zip(*self.scenes))
    run = lambda w, t, m: rollout.rollout_batch(
        self.predictor, self.params, w, t, m, 2, self.problem.context,
        self.problem.spec)
    with self.assertRaisesRegex(ValueError, "one length.*3, 2 and 3"):
      run(windows, types[:2], moving)
    with self.assertRaisesRegex(ValueError, r"scene 1: window must be "
                                r"\[C, N, 2\].*\(6, \d+\)"):
      run([windows[0], windows[1][..., 0]] + windows[2:], types, moving)
    with self.assertRaisesRegex(ValueError, "scene 2: types must be"):
      run(windows, types[:2] + [types[2][:-1]], moving)
    with self.assertRaisesRegex(ValueError, "scene 1 has 5 input frames"):
      run([windows[0], windows[1][1:]] + windows[2:], types, moving)
    with self.assertRaisesRegex(ValueError, "no scenes"):
      run([], [], [])


def resting_scene(num_particles: int, x: float, radius: float):
  """(scene, window [C, N, 2], types, moving): the small config's sand
  (spacing 0.01 m) at rest above a semicircle obstacle, then its boundary."""
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
  return scene, window, types, moving


@pytest.mark.slow  # ~1 min on 2 CPU cores: 2000 + 2 x 600 model steps.
class PretrainedStabilityTest(absltest.TestCase):
  """Long rollouts of the shipped small model stay finite and in the domain.

  The sand starts at rest, as the MPM's does. (The model keeps a resting heap
  nearly still, so this guards against blow-ups, not against drift.)
  """

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.scenes = [resting_scene(200, 0.9, 0.04), resting_scene(180, 0.7, 0.03)]
    domain = cls.scenes[0][0].domain
    cls.bounds = np.array([[0.0, domain.width], [0.0, domain.height]])
    # From the checkpoint alone (its stored config and statistics).
    _, cls.problem, trainer, state, _ = evaluate.load_run(
        tasks.PRETRAINED, scene=cls.scenes[0][0])
    cls.params = state.params
    cls.predictor = simulator.ModelPredictor(trainer.model)

  def _assert_in_domain(self, positions):
    self.assertTrue(np.all(np.isfinite(positions)))
    margin = 3 * self.problem.radius
    out = np.any((positions < self.bounds[:, 0] - margin) |
                 (positions > self.bounds[:, 1] + margin), axis=-1)
    steps, nodes = np.nonzero(out)
    self.assertFalse(out.any(), f"{len(set(nodes))} nodes leave the domain, "
                     f"first at step {steps.min() if out.any() else None}")

  def test_2000_steps_stay_finite_in_the_domain(self):
    _, window, types, moving = self.scenes[0]
    start = time.perf_counter()
    pred = rollout.rollout(self.predictor, self.params, window, types, moving,
                           2000, self.problem.context, self.problem.spec)
    print(f"2000-step rollout: {time.perf_counter() - start:.1f} s")
    self.assertEqual(pred.shape, (2000,) + window.shape[1:])
    self._assert_in_domain(pred)

  def test_600_batched_steps_stay_finite_in_the_domain(self):
    _, windows, types, moving = map(list, zip(*self.scenes))
    self.assertNotEqual(len(types[0]), len(types[1]))
    start = time.perf_counter()
    preds = rollout.rollout_batch(self.predictor, self.params, windows, types,
                                  moving, 600, self.problem.context,
                                  self.problem.spec)
    print(f"600-step batched rollout: {time.perf_counter() - start:.1f} s")
    for w, pred in zip(windows, preds):
      self.assertEqual(pred.shape, (600,) + w.shape[1:])
      self._assert_in_domain(pred)


if __name__ == "__main__":
  absltest.main()
