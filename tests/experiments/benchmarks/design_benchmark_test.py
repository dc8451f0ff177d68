"""Tests for `experiments.benchmarks.design_benchmark`."""

from absl.testing import absltest
import pytest

from experiments import tasks
from experiments.benchmarks import design_benchmark
from gnsjax import design
from gnsjax import objectives


@pytest.mark.slow  # compiles an MPM rollout and its gradient three times
class MeasureTest(absltest.TestCase):

  def test_memory_at_full_frames_is_of_the_longer_program(self):
    scene = tasks.design_scene("semicircle", (0.04,), 1.0, 3)
    objective = objectives.make("passed_fraction", x_protect=0.4).smooth
    sim = design.MPMRollout(design.Placement(scene))
    short = design_benchmark.measure("short", sim, objective, 3, 3, 1,
                                     log=lambda _: None)
    sim = design.MPMRollout(design.Placement(scene))
    row = design_benchmark.measure("long", sim, objective, 3, 30, 1,
                                   log=lambda _: None)
    self.assertGreater(row["forward_s"], 0)
    self.assertGreater(row["gradient_s"], 0)
    self.assertEqual(row["memory_frames"], 30)
    # A re-used jit would hand back the 3-frame trace (same memory).
    self.assertGreater(row["total_gb"], short["total_gb"])


if __name__ == "__main__":
  absltest.main()
