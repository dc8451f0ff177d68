"""Tests for `experiments.benchmarks.dataset_benchmark`."""

from absl.testing import absltest

from experiments.benchmarks import dataset_benchmark
from tests.gnsjax import fixtures as gnsjax_fixtures


class ReadingTest(absltest.TestCase):

  def test_reading_rates_of_a_tiny_dataset(self):
    out = dataset_benchmark.time_reading(gnsjax_fixtures.tiny_dataset(),
                                         windows=20, batch_size=2, batches=3)
    self.assertGreater(out["windows_per_s"], 0)
    self.assertGreater(out["batches_per_s"], 0)
    self.assertEqual(out["batch_size"], 2)


if __name__ == "__main__":
  absltest.main()
