"""Tests for `experiments.benchmarks.gns_programs`."""

from unittest import mock

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from experiments.benchmarks import gns_inputs
from experiments.benchmarks import gns_programs
from gnsjax import features
from gnsjax import models
from tests.experiments.benchmarks import fixtures


class DenseFlopsTest(absltest.TestCase):

  def test_dense_flops_are_the_bulk_of_xla_count(self):
    n, e, f = 200, 2000, gns_programs.node_feature_size()
    self.assertEqual(f, features.num_node_features(6))  # 10 + 3 (SDF)
    rng = np.random.default_rng(0)
    args = (jnp.asarray(rng.normal(size=(n, f)), jnp.float32),
            jnp.zeros((n,), jnp.int32),
            jnp.asarray(rng.normal(size=(e, 3)), jnp.float32),
            jnp.asarray(rng.integers(0, n, e), jnp.int32),
            jnp.asarray(rng.integers(0, n, e), jnp.int32))
    for split in (True, False):
      model = models.EncodeProcessDecode(
          latent_size=64, num_message_passing_steps=2,
          split_first_layer=split)
      params = models.init_params(model, jax.random.key(0), f)
      cost = jax.jit(model.apply).lower(params, *args).compile()
      cost = cost.cost_analysis()
      xla = (cost[0] if isinstance(cost, list) else cost)["flops"]
      dense = gns_programs.dense_flops(model, n, e, f)
      # XLA also counts LayerNorms, ReLUs, residuals and gathers' adds.
      self.assertLess(dense["total"], xla)
      self.assertGreater(dense["total"], 0.8 * xla)


class RunnerTest(absltest.TestCase):

  def test_forward_and_training_step_on_the_sand_block(self):
    d = fixtures.tempdir(self)
    n_edges = fixtures.write_sand_block(d)
    with mock.patch.object(gns_inputs, "SAND_BLOCK_EDGES", n_edges):
      g = gns_inputs.load_sand_block(d)
    runner = gns_programs.Runner(gns_programs.load_config("test"), g)
    # The model sees the paper scene's SDF grid at R / 6.
    self.assertAlmostEqual(runner.inputs.solids.spacing, g.radius / 6)
    runner.compile_forward()
    acc = np.asarray(runner.forward())
    self.assertEqual(acc.shape, (g.n_nodes, 2))
    self.assertTrue(np.all(np.isfinite(acc)))
    runner.compile_train()
    self.assertTrue(np.isfinite(float(runner.train_step())))
    self.assertEqual(int(runner.state.step), 1)
    self.assertGreater(runner.dense_flops()["total"], 0)


if __name__ == "__main__":
  absltest.main()
