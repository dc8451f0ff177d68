"""Tests for `gnsjax.rollout`."""

import dataclasses

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import data
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import rollout
from gnsjax import simulator
from gnsjax import train
from tests.gnsjax import fixtures

C = 6


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
    model = models.EncodeProcessDecode(latent_size=16, hidden_layers=1,
                                       num_message_passing_steps=2,
                                       type_embedding_size=4)
    node_f = jnp.zeros((window.shape[1], 2 * (C - 1) + 4))
    params = model.init(jax.random.key(0), node_f, jnp.asarray(types),
                        jnp.zeros((4, 3)), jnp.zeros(4, jnp.int32),
                        jnp.zeros(4, jnp.int32))
    predictor = simulator.ModelPredictor(model)
    spec = self.problem.spec
    # A list allocated for the same nodes spread on a lattice wider than the
    # radius (self-edges only): it overflows at the first real update.
    bounds = np.asarray(spec.bounds)
    columns = int((bounds[0, 1] - bounds[0, 0]) // (1.05 * spec.radius))
    cells = np.stack(np.divmod(np.arange(window.shape[1]), columns), -1)
    spread = bounds[:, 0] + 1.05 * spec.radius * cells[:, ::-1]
    self.assertTrue(np.all(spread <= bounds[:, 1]))
    small = graph.allocate(spec, jnp.asarray(spread, jnp.float32))
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


if __name__ == "__main__":
  absltest.main()
