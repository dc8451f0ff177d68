"""Tests for `experiments.benchmarks.gns_benchmark` and `--what=gns`."""

import json
import os
import tempfile
from unittest import mock

from absl import flags
from absl.testing import absltest
from absl.testing import flagsaver
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.benchmarks import __main__ as benchmarks_main
from experiments.benchmarks import gns_benchmark
from experiments.benchmarks import gns_report
from gnsjax import models
from tests.experiments.benchmarks import fixtures

FLAGS = flags.FLAGS
# The shared window the peers were timed on, where a machine has it.
SHARED_SAND_BLOCK_DIR = os.environ.get("GNSJAX_SAND_BLOCK_DIR")


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


class SandBlockTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    self.dir = fixtures.tempdir(self)
    self.n_edges = fixtures.write_sand_block(self.dir)

  def test_window_and_graph(self):
    # The check of the peers' edge count, against this window's count.
    with mock.patch.object(gns_benchmark, "SAND_BLOCK_EDGES", self.n_edges):
      g = gns_benchmark.load_sand_block(self.dir)
    self.assertEqual(g.n_edges, self.n_edges)
    self.assertEqual(g.positions.shape, (7, 1000, 2))
    self.assertTrue(np.all(g.moving))
    # The padded list holds the same edges plus padding pointing at N.
    real = g.padded_senders < g.n_nodes
    np.testing.assert_array_equal(g.padded_senders[real], g.senders)

  def test_other_edge_count_is_refused(self):
    with self.assertRaisesRegex(RuntimeError, "want 24930"):
      gns_benchmark.load_sand_block(self.dir)

  def test_missing_input_is_named(self):
    with tempfile.TemporaryDirectory() as empty:
      with self.assertRaisesRegex(FileNotFoundError, "sand_block_window.npz"):
        gns_benchmark.load_sand_block(empty)


@pytest.mark.skipif(not SHARED_SAND_BLOCK_DIR,
                    reason="$GNSJAX_SAND_BLOCK_DIR (the shared window) unset")
class SharedSandBlockTest(absltest.TestCase):

  def test_graph_has_the_peers_edge_count(self):
    g = gns_benchmark.load_sand_block(SHARED_SAND_BLOCK_DIR)
    self.assertEqual(g.n_edges, gns_benchmark.SAND_BLOCK_EDGES)
    self.assertEqual(g.positions.shape, (7, 1000, 2))
    self.assertTrue(np.all(g.moving))
    real = g.padded_senders < g.n_nodes
    np.testing.assert_array_equal(g.padded_senders[real], g.senders)
    self.assertTrue(gns_report.check_quotes(os.path.join(
        SHARED_SAND_BLOCK_DIR, gns_benchmark.SAND_BLOCK_README))[
            "readme_checked"])


class QuotesTest(absltest.TestCase):

  def test_readme_quoting_the_peers_is_checked(self):
    d = fixtures.tempdir(self)
    fixtures.write_sand_block(d)
    readme = os.path.join(d, "README.md")
    self.assertEqual(gns_report.check_quotes(readme),
                     {"quoted_from": readme, "readme_checked": True})

  def test_readme_with_other_figures_is_refused(self):
    readme = os.path.join(fixtures.tempdir(self), "README.md")
    with open(readme, "w") as f:
      f.write("geoelements/gns 0.50 s and 1.53 s")
    with self.assertRaisesRegex(ValueError, "0.54 s"):
      gns_report.check_quotes(readme)

  def test_missing_readme_is_recorded_not_fatal(self):
    readme = os.path.join(fixtures.tempdir(self), "README.md")
    self.assertFalse(gns_report.check_quotes(readme)["readme_checked"])

  def test_peers_are_compared_with_the_quoted_times(self):
    row = {"forward": {"median_s": 0.27, "min_s": 0.27},
           "train_step": {"median_s": 1.53, "min_s": 1.0}}
    out = gns_report.compare_peers(row, {"quoted_from": "README.md",
                                         "readme_checked": True})
    ref = out["peers"][gns_report.REFERENCE_PEER]
    self.assertAlmostEqual(ref["forward_ratio"], 0.5)
    self.assertAlmostEqual(ref["train_step_ratio"], 1.0)
    self.assertTrue(out["forward_target_met"])
    self.assertFalse(out["train_step_target_met"])
    self.assertEqual(out["quoted_from"], "README.md")


@pytest.mark.slow  # 25-80 s on 2 CPU cores: a dozen compilations.
class GnsBenchmarkQuickTest(absltest.TestCase):

  def test_quick_mode_writes_and_prints_results(self):
    if not FLAGS.is_parsed():
      FLAGS.mark_as_parsed()
    out = fixtures.tempdir(self)
    sand_block = fixtures.tempdir(self)
    n_edges = fixtures.write_sand_block(sand_block)
    with flagsaver.flagsaver(out=out, quick=True, what=["gns"],
                             sand_block_dir=sand_block), \
         mock.patch.object(gns_benchmark, "SAND_BLOCK_EDGES", n_edges):
      benchmarks_main.main(["benchmarks"])

    self.assertFalse(os.path.exists(os.path.join(out,
                                                 "mpm_benchmark_quick.json")))
    with open(os.path.join(out, "gns_benchmark_quick.json")) as f:
      results = json.load(f)
    with open(os.path.join(out, "gns_benchmark_quick.md")) as f:
      markdown = f.read()
    self.assertIn("## Split first edge layer vs concatenated", markdown)
    self.assertIn("## Where the time goes", markdown)
    self.assertEqual(results["scenes"]["sand_block"]["n_edges"], n_edges)
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
