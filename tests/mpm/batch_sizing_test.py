"""Tests for `mpm.batch_sizing`: scenes per batch from memory."""

import dataclasses

from absl.testing import absltest

import mpm
from mpm import batch_sizing
from mpm import simulation

SCENE = mpm.sample_scene(3, num_particles=150, num_frames=5, spacing=0.01)


@dataclasses.dataclass
class FakeDevice:
  """A device reporting memory as an accelerator does."""
  stats: dict | None
  platform: str = "gpu"

  def memory_stats(self):
    return self.stats


class BatchSizingTest(absltest.TestCase):

  def test_device_memory(self):
    self.assertEqual(batch_sizing.device_memory_bytes(FakeDevice(
        {"bytes_limit": 1000, "bytes_in_use": 300})), 700)
    self.assertIsNone(batch_sizing.device_memory_bytes(FakeDevice(None)))

  def test_the_batch_fills_the_memory_and_one_more_does_not_fit(self):
    s = simulation.setup(SCENE)
    one = batch_sizing.program_bytes([s], chunk_frames=4)
    two = batch_sizing.program_bytes([s, s], chunk_frames=4)
    self.assertGreater(two, one)
    # Memory for about three scenes at fraction 0.5.
    limit = int(2 * (one + 2.5 * (two - one)))
    sizing = batch_sizing.batch_size_for(
        SCENE, chunk_frames=4, fraction=0.5,
        device=FakeDevice({"bytes_limit": limit}))
    self.assertEqual(sizing.available_bytes, limit)
    self.assertIn("memory_stats", sizing.source)
    self.assertGreaterEqual(sizing.batch, 2)
    fits = batch_sizing.program_bytes([s] * sizing.batch, chunk_frames=4)
    over = batch_sizing.program_bytes([s] * (sizing.batch + 1), chunk_frames=4)
    self.assertLessEqual(fits, 0.5 * limit)
    self.assertGreater(over, 0.5 * limit)

  def test_fallback_without_memory_stats(self):
    sizing = batch_sizing.batch_size_for(SCENE, chunk_frames=4, cpu_batch=5,
                                       device=FakeDevice(None, "cpu"))
    self.assertEqual(sizing.batch, 5)
    self.assertIsNone(sizing.available_bytes)
    self.assertIn("fallback: cpu reports no memory_stats", sizing.source)


if __name__ == "__main__":
  absltest.main()
