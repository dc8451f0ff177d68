"""Tests for `experiments.benchmarks.input_benchmark`."""

import json
import shutil
import tempfile
import os

from absl.testing import absltest

from experiments.benchmarks import input_benchmark
from tests.gnsjax import fixtures as gnsjax_fixtures


class InputBenchmarkTest(absltest.TestCase):

  def test_quick_run_writes_every_feed_rate(self):
    out = tempfile.mkdtemp()
    self.addCleanup(shutil.rmtree, out)
    record = input_benchmark.run_benchmark(
        gnsjax_fixtures.tiny_dataset(), out, quick=True,
        config=gnsjax_fixtures.tiny_config())
    self.assertEqual(set(record["batches_per_s"]),
                     {"host", "device", "device_graph"})
    for rate in record["batches_per_s"].values():
      self.assertGreater(rate, 0)
    with open(os.path.join(out, "input_benchmark_quick.json")) as f:
      self.assertIn("batches_per_s", json.load(f))


if __name__ == "__main__":
  absltest.main()
