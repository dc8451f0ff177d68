"""Tests for `experiments.benchmarks.op_profile`."""

from absl.testing import absltest
import jax
import jax.numpy as jnp

from experiments.benchmarks import op_profile


class OpProfileTest(absltest.TestCase):

  def test_op_profile_classifies_dots_gathers_scatters(self):
    idx = jnp.array([0, 2, 2, 1], jnp.int32)

    def fn(x, w):
      y = jnp.tanh(x @ w)                       # dense (+ fused elementwise)
      g = y[idx]                                # gather
      return jax.ops.segment_sum(jnp.exp(g), idx, 3)  # scatter

    args = (jnp.ones((3, 64)), jnp.ones((64, 64)))
    # As production compiles it: the suite's classic emitters
    # (tests/conftest.py) would fuse the scatter into a loop.
    compiled = jax.jit(fn).lower(*args).compile(
        {"xla_cpu_use_fusion_emitters": True})
    kinds = set(op_profile.classify(compiled.as_text()).values())
    self.assertContainsSubset({"dense", "scatter"}, kinds)
    out = op_profile.breakdown(compiled, lambda: compiled(*args), repeats=1)
    if "skipped" not in out:
      self.assertAlmostEqual(sum(out["share"].values()), 1.0)
      self.assertGreater(out["total_s"], 0)


if __name__ == "__main__":
  absltest.main()
