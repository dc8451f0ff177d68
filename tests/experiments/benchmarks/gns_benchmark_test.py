"""Tests for `experiments.benchmarks.gns_benchmark` and `--what=gns`."""

import json
import os
import tempfile

from absl import flags
from absl.testing import absltest
from absl.testing import flagsaver
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.benchmarks import __main__ as benchmarks_main
from experiments.benchmarks import gns_benchmark
from experiments.benchmarks import op_profile
from gnsjax import models

FLAGS = flags.FLAGS
HAS_SAND_BLOCK = os.path.exists(os.path.join(
    gns_benchmark.SAND_BLOCK_DIR, gns_benchmark.SAND_BLOCK_NPZ))


class HelpersTest(absltest.TestCase):

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
      dense = gns_benchmark.dense_flops(model, n, e, 14)
      # XLA also counts LayerNorms, ReLUs, residuals and gathers' adds.
      self.assertLess(dense["total"], xla)
      self.assertGreater(dense["total"], 0.8 * xla)

  def test_op_profile_classifies_dots_gathers_scatters(self):
    idx = jnp.array([0, 2, 2, 1], jnp.int32)

    def fn(x, w):
      y = jnp.tanh(x @ w)                       # dense (+ fused elementwise)
      g = y[idx]                                # gather
      return jax.ops.segment_sum(jnp.exp(g), idx, 3)  # scatter

    args = (jnp.ones((3, 64)), jnp.ones((64, 64)))
    compiled = jax.jit(fn).lower(*args).compile()
    kinds = set(op_profile.classify(compiled.as_text()).values())
    self.assertContainsSubset({"dense", "scatter"}, kinds)
    out = op_profile.breakdown(compiled, lambda: compiled(*args), repeats=1)
    if "skipped" not in out:
      self.assertAlmostEqual(sum(out["share"].values()), 1.0)
      self.assertGreater(out["total_s"], 0)

  def test_what_flag_refuses_unknown_benchmarks(self):
    if not FLAGS.is_parsed():
      FLAGS.mark_as_parsed()
    with flagsaver.flagsaver():
      FLAGS.what = ["gns"]
      with self.assertRaisesRegex(flags.IllegalFlagValueError, "subset"):
        FLAGS.what = ["mpm", "lbm"]


@pytest.mark.skipif(not HAS_SAND_BLOCK, reason="shared sand block missing")
class SandBlockTest(absltest.TestCase):

  def test_graph_has_the_peers_edge_count(self):
    g = gns_benchmark.load_sand_block()
    self.assertEqual(g.n_edges, gns_benchmark.SAND_BLOCK_EDGES)
    self.assertEqual(g.positions.shape, (7, 1000, 2))
    self.assertTrue(np.all(g.moving))
    # The padded list holds the same edges plus padding pointing at N.
    real = g.padded_senders < g.n_nodes
    np.testing.assert_array_equal(g.padded_senders[real], g.senders)

  def test_missing_input_is_named(self):
    with tempfile.TemporaryDirectory() as empty:
      with self.assertRaisesRegex(FileNotFoundError, "sand_block_window.npz"):
        gns_benchmark.load_sand_block(empty)


@pytest.mark.slow  # 25-80 s on 2 CPU cores: a dozen compilations.
@pytest.mark.skipif(not HAS_SAND_BLOCK, reason="shared sand block missing")
class GnsBenchmarkQuickTest(absltest.TestCase):

  def test_quick_mode_writes_and_prints_results(self):
    if not FLAGS.is_parsed():
      FLAGS.mark_as_parsed()
    out = self.create_tempdir().full_path
    with flagsaver.flagsaver(out=out, quick=True, what=["gns"]):
      benchmarks_main.main(["benchmarks"])

    self.assertFalse(os.path.exists(os.path.join(out,
                                                 "mpm_benchmark_quick.json")))
    with open(os.path.join(out, "gns_benchmark_quick.json")) as f:
      results = json.load(f)
    with open(os.path.join(out, "gns_benchmark_quick.md")) as f:
      markdown = f.read()
    self.assertIn("## Split first edge layer vs concatenated", markdown)
    self.assertIn("## Where the time goes", markdown)
    self.assertEqual(results["scenes"]["sand_block"]["n_edges"], 24_930)
    self.assertGreater(results["scenes"]["paper_scene"]["n_boundary"], 0)
    sizes = gns_benchmark.QUICK
    self.assertLen(results["steps"], 2 * len(sizes.models) + 1)
    for row in results["steps"]:
      self.assertGreater(row["forward"]["median_s"], 0)
      self.assertGreater(row["forward_matmul_fraction_dense"], 0)
    self.assertGreater(results["matmul"]["median_gflops"], 0)
    split = results["split"]
    self.assertLess(split["max_abs_output_diff"], 1e-4)
    self.assertGreater(split["processor_flops_saved"], 0)
    self.assertGreater(split["forward_speedup"], 0)
    self.assertEqual(set(split["profile"]), {
        "split_forward", "split_train_step", "concat_forward",
        "concat_train_step"})
    for p in split["profile"].values():
      if "skipped" not in p:
        self.assertAlmostEqual(sum(p["share"].values()), 1.0)
        self.assertGreater(p["seconds"]["dense"], 0)
    # Peers are compared only for the paper model (not in quick mode).
    self.assertNotIn("peers", results)


if __name__ == "__main__":
  absltest.main()
