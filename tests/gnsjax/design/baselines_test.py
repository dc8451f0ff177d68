"""Tests for `gnsjax.design.baselines`: budgets, and the minimum of closed
forms found inside the box."""

import time

from absl.testing import absltest
from absl.testing import parameterized
import numpy as np

from gnsjax.design import baselines
from gnsjax.design import objectives
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from tests.gnsjax.design.fixtures import TWO_OBSTACLES
from tests.gnsjax.design.fixtures import scene

LOW = np.array([0.5, 0.02, 0.5, 0.02])
HIGH = np.array([1.3, 0.05, 1.3, 0.05])
# The minimum, inside the box; the parameters' scales differ 30-fold like
# positions and radii.
MINIMUM = np.array([0.8, 0.03, 1.1, 0.045])


def bowl(vectors):
  """A quadratic with its minimum 0 at MINIMUM, in units of the box."""
  return np.sum(((vectors - MINIMUM) / (HIGH - LOW))**2, axis=1)


def counting(fn, calls):
  def wrapped(vectors):
    calls.append(len(vectors))
    return fn(vectors)
  return wrapped


class BudgetTest(parameterized.TestCase):

  @parameterized.parameters("random", "sweep", "cmaes")
  def test_evaluation_budget_is_exact(self, method):
    calls = []
    trace = baselines.run(method, counting(bowl, calls), LOW, HIGH,
                          (LOW + HIGH) / 2, budget=baselines.Budget(21),
                          batch_size=8, points=3)
    self.assertLen(trace, 21)
    self.assertEqual(sum(calls), 21)
    self.assertLessEqual(max(calls), 8)
    # The best so far is the running minimum of the values.
    np.testing.assert_allclose([r["best"] for r in trace],
                               np.minimum.accumulate([r["value"]
                                                      for r in trace]))

  @parameterized.parameters("random", "sweep", "cmaes")
  def test_wall_time_budget_stops_within_one_batch(self, method):
    def slow(vectors):
      time.sleep(0.05)
      return bowl(vectors)

    start = time.perf_counter()
    trace = baselines.run(method, slow, LOW, HIGH, (LOW + HIGH) / 2,
                          budget=baselines.Budget(seconds=0.3), batch_size=4,
                          points=5)
    seconds = time.perf_counter() - start
    self.assertLess(seconds, 0.3 + 0.05 + 0.1)  # one batch late at most
    # Every batch started before the budget ran out: 0.3 / 0.05.
    self.assertBetween(len(trace) // 4, 5, 7)
    self.assertLess(trace[-1]["seconds"], 0.3 + 0.1)

  def test_the_sweep_ends_with_its_grid(self):
    trace = baselines.grid_sweep(bowl, LOW, HIGH, points=2,
                                 budget=baselines.Budget(100))
    self.assertLen(trace, 16)
    got = sorted(map(tuple, np.round([r["vector"] for r in trace], 6)))
    want = sorted(map(tuple, np.round(baselines.grid_points(LOW, HIGH, 2),
                                      6)))
    self.assertEqual(got, want)

  def test_no_budget_is_refused(self):
    with self.assertRaisesRegex(ValueError, "evaluations or seconds"):
      baselines.random_search(bowl, LOW, HIGH, budget=baselines.Budget())
    with self.assertRaisesRegex(ValueError, "unknown 'nope'"):
      baselines.run("nope", bowl, LOW, HIGH, LOW, budget=baselines.Budget(1))


class MinimumTest(absltest.TestCase):

  def test_cmaes_finds_the_minimum_of_a_bowl(self):
    trace = baselines.cmaes(bowl, LOW, HIGH, (LOW + HIGH) / 2,
                            budget=baselines.Budget(800), batch_size=8)
    best = min(trace, key=lambda r: r["value"])
    self.assertLess(best["value"], 1e-6)
    np.testing.assert_allclose(best["vector"], MINIMUM,
                               atol=1e-3 * (HIGH - LOW).max())

  def test_cmaes_finds_a_minimum_on_the_box_edge(self):
    # The unconstrained minimum lies outside: the best is its projection.
    outside = np.array([1.5, 0.03, 0.3, 0.045])
    fn = lambda v: np.sum(((v - outside) / (HIGH - LOW))**2, axis=1)
    trace = baselines.cmaes(fn, LOW, HIGH, (LOW + HIGH) / 2,
                            budget=baselines.Budget(800), batch_size=8)
    best = np.asarray(min(trace, key=lambda r: r["value"])["vector"])
    np.testing.assert_allclose(best, np.clip(outside, LOW, HIGH), atol=2e-3)
    self.assertTrue(np.all(best >= LOW) and np.all(best <= HIGH))

  def test_random_search_gets_close_to_the_minimum(self):
    # 2000 uniform draws in 4-D: the nearest lies within about a tenth of
    # the box of the minimum (expected distance 0.09 of a unit side).
    trace = baselines.random_search(bowl, LOW, HIGH,
                                    budget=baselines.Budget(2000),
                                    batch_size=50)
    vectors = np.asarray([r["vector"] for r in trace])
    self.assertTrue(np.all(vectors >= LOW) and np.all(vectors <= HIGH))
    best = min(trace, key=lambda r: r["value"])
    self.assertLess(best["value"], 0.15**2)
    self.assertEqual(best["value"], bowl(vectors).min())

  def test_repair_is_applied_before_evaluation(self):
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES))
    project = lambda vs: np.stack([p.to_vector(p.project(p.from_vector(v)))
                                   for v in vs])
    trace = baselines.random_search(bowl, LOW, HIGH,
                                    budget=baselines.Budget(64),
                                    project=project)
    for r in trace:
      p.check(p.from_vector(r["vector"]))   # never overlapping


class MPMBatchObjectiveTest(absltest.TestCase):

  def test_batch_equals_one_rollout_at_a_time(self):
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES,
                                           num_frames=20))
    sim = rollouts.MPMRollout.create(p)
    obj = objectives.make("runout")
    fn = baselines.MPMBatchObjective(sim, obj.plain, batch_size=4)
    vectors = np.array([[1.28, 0.03, 1.225, 0.02],
                        [1.25, 0.04, 1.15, 0.03],
                        [1.2, 0.02, 1.29, 0.05]])
    got = fn(vectors)   # 3 of 4: padded
    driver = rollouts.MPMDriver(sim)
    want = [obj.plain(driver.rollout(p.from_vector(v))) for v in vectors]
    np.testing.assert_allclose(got, want, atol=1e-6)
    self.assertGreater(np.ptp(got), 1e-3)   # the designs differ


if __name__ == "__main__":
  absltest.main()
