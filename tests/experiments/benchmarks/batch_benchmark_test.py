"""Tests for `experiments.benchmarks.batch_benchmark`."""

import json
import os
import tempfile

from absl.testing import absltest

from experiments.benchmarks import batch_benchmark


class BatchBenchmarkTest(absltest.TestCase):

  def test_quick_run_writes_consistent_figures(self):
    with tempfile.TemporaryDirectory() as d:
      results = batch_benchmark.run_benchmark(d, quick=True, log=lambda _: 0)
      with open(os.path.join(d, "batch_benchmark_quick.json")) as f:
        stored = json.load(f)
      with open(os.path.join(d, "batch_benchmark_quick.md")) as f:
        markdown = f.read()
    self.assertEqual(stored["measured"], results["measured"])
    m = stored["measured"]
    self.assertEqual([r["batch"] for r in m["rows"]], [1, 2])
    for r in m["rows"]:  # the rate is the work over the median time
      self.assertEqual(r["particle_substeps"], r["batch"] * 100 * m["frames"]
                       * m["n_substeps_per_frame"])
      self.assertGreater(r["particle_substeps_per_s"], 0)
    self.assertIn("no GPU was available", markdown)
    self.assertIn("fallback: cpu reports no memory_stats", markdown)


if __name__ == "__main__":
  absltest.main()
