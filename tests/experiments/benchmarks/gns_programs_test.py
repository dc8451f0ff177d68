"""Tests for `experiments.benchmarks.gns_programs`."""

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from experiments.benchmarks import gns_programs
from gnsjax import models


class DenseFlopsTest(absltest.TestCase):

  def test_dense_flops_are_the_bulk_of_xla_count(self):
    n, e = 200, 2000
    rng = np.random.default_rng(0)
    args = (jnp.asarray(rng.normal(size=(n, 14)), jnp.float32),
            jnp.zeros((n,), jnp.int32),
            jnp.asarray(rng.normal(size=(e, 3)), jnp.float32),
            jnp.asarray(rng.integers(0, n, e), jnp.int32),
            jnp.asarray(rng.integers(0, n, e), jnp.int32))
    for split in (True, False):
      model = models.EncodeProcessDecode(
          latent_size=64, num_message_passing_steps=2,
          split_first_layer=split)
      params = model.init(jax.random.key(0), *args)
      cost = jax.jit(model.apply).lower(params, *args).compile()
      cost = cost.cost_analysis()
      xla = (cost[0] if isinstance(cost, list) else cost)["flops"]
      dense = gns_programs.dense_flops(model, n, e, 14)
      # XLA also counts LayerNorms, ReLUs, residuals and gathers' adds.
      self.assertLess(dense["total"], xla)
      self.assertGreater(dense["total"], 0.8 * xla)


if __name__ == "__main__":
  absltest.main()
