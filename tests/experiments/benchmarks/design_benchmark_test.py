"""Tests for `experiments.benchmarks.design_benchmark`."""

from absl.testing import absltest
import pytest

from experiments.benchmarks import design_benchmark
from experiments.configs import test as configs_test
from gnsjax import design
from gnsjax.design import objectives
from gnsjax.design import scenes


@pytest.mark.slow  # compiles an MPM rollout and its gradient three times
class MeasureTest(absltest.TestCase):

  def test_memory_at_full_frames_is_of_the_longer_program(self):
    scene = scenes.one_obstacle("semicircle", (0.04,), 1.0, 3)
    objective = objectives.make("passed_fraction", x_protect=0.4).smooth
    driver = design.MPMDriver(design.MPMRollout.create(
        design.Placement(scene)))
    short = design_benchmark.measure("short", driver, objective, 3, 3, 1,
                                     log=lambda _: None)
    row = design_benchmark.measure("long", driver, objective, 3, 30, 1,
                                   log=lambda _: None)
    self.assertGreater(row["forward_s"], 0)
    self.assertGreater(row["gradient_s"], 0)
    self.assertEqual(row["memory_frames"], 30)
    self.assertEqual(row["timed_steps"], 2)
    # The 30-frame program is another trace (num_frames is static), not
    # the cached 3-frame one.
    self.assertGreater(row["total_gb"], short["total_gb"])


@pytest.mark.slow  # an MPM window, then a GNS rollout and gradient compiled
class GnsMeasureTest(absltest.TestCase):

  def test_gns_row_of_an_untrained_model(self):
    scene = scenes.one_obstacle("semicircle", (0.04,), 1.0, 8)
    placement = design.Placement(scene)
    model, params, problem = design_benchmark.untrained_gns(
        placement, configs_test.get_config())
    window = design.mpm_window(scene, problem.input_frames,
                               problem.frame_stride)
    driver = design.GNSDriver(design.GNSRollout.create(
        placement, model, problem, window), params)
    objective = objectives.make("passed_fraction", x_protect=0.4).smooth
    row = design_benchmark.measure("gns", driver, objective, 8, 10, 1,
                                   log=lambda _: None)
    self.assertEqual(row["timed_steps"], 2)   # frames 6 and 7
    self.assertEqual(row["particles_or_nodes"], len(driver.sim.types))
    self.assertGreater(row["forward_s"], 0)
    self.assertGreater(row["gradient_s"], 0)
    self.assertEqual(row["memory_frames"], 10)
    self.assertGreater(row["total_gb"], 0)


if __name__ == "__main__":
  absltest.main()
