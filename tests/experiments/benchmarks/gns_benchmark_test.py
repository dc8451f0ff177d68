"""Tests for `experiments.benchmarks.gns_benchmark` and `--what=gns`."""

import json
import os
from unittest import mock

from absl import flags
from absl.testing import absltest
from absl.testing import flagsaver
import pytest

from experiments.benchmarks import __main__ as benchmarks_main
from experiments.benchmarks import gns_benchmark
from experiments.benchmarks import gns_inputs
from tests.experiments.benchmarks import fixtures

FLAGS = flags.FLAGS


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
         mock.patch.object(gns_inputs, "SAND_BLOCK_EDGES", n_edges):
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
    # Both graphs see the paper scene's SDF (13 node features), and the
    # report says so beside the 14 of figures recorded before.
    for scene in results["scenes"].values():
      self.assertEqual(scene["n_node_features"], 13)
      self.assertEqual(scene["sdf_scene"], "paper_semicircle")
    self.assertIn("Node features: 13", markdown)
    self.assertIn("had 14", markdown)
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
