"""Tests for `gnsjax.design.comparison`: every method under one budget on a
tiny two-obstacle scene, judged and verified by the MPM."""

import csv
import os
import tempfile

from absl.testing import absltest
import numpy as np

from gnsjax.design import baselines
from gnsjax.design import comparison
from gnsjax.design import objectives
from gnsjax.design import placement as placement_lib
from tests.gnsjax.design.fixtures import TWO_OBSTACLES
from tests.gnsjax.design.fixtures import scene


class CompareTest(absltest.TestCase):

  def test_every_method_within_its_budget_and_verified(self):
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES,
                                           num_frames=12))
    out = tempfile.mkdtemp()
    summary = comparison.compare(
        out, p, objectives.make("runout"), comparison.METHODS,
        baselines.Budget(evaluations=4), learning_rate=0.01, sigma=0.01,
        num_samples=2, batch_size=2, sweep_points=2, log=lambda _: None)
    for name in ("trace.csv", "summary.json", "report.md",
                 "objective_vs_time.png"):
      self.assertTrue(os.path.exists(os.path.join(out, name)), name)
    lo, hi = p.bounds()
    with open(os.path.join(out, "trace.csv")) as f:
      rows = list(csv.DictReader(f))
    for run in summary["runs"]:
      self.assertEqual(run["evaluations"], 4, run["method"])
      mine = [r for r in rows if r["method"] == run["method"]]
      self.assertLen(mine, 4)
      values = [float(r["value"]) for r in mine]
      self.assertAlmostEqual(run["best"], min(values), places=6)
      # The re-simulation agrees with the value the search saw.
      self.assertAlmostEqual(run["verified"], run["best"], delta=1e-5)
      for r in mine:   # every design in range and apart
        v = np.asarray([float(r[n]) for n in p.names])
        self.assertTrue(np.all(v >= lo - 1e-6) and np.all(v <= hi + 1e-6))
        p.check(p.from_vector(v))
    self.assertIn(summary["winner"], comparison.METHODS)
    with open(os.path.join(out, "report.md")) as f:
      self.assertIn("| cmaes | 4 |", f.read())

  def test_step_scale_follows_the_ranges(self):
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES))
    s = comparison.step_scale(p, p.initial())
    np.testing.assert_allclose(s["x"], [1, 1])
    np.testing.assert_allclose(s["size"], np.full((2, 2), 0.03 / 0.8),
                               rtol=1e-5)



class BafflesTest(absltest.TestCase):

  def test_a_row_of_baffles_in_range_and_kept_apart(self):
    scene = comparison.baffles_scene(6, num_frames=2)
    shapes = {(o.shape, o.width, o.height) for o in scene.obstacles}
    self.assertEqual(shapes, {("rectangle",) + comparison.BAFFLE_SIZE})
    p = placement_lib.MultiPlacement(scene, indices=tuple(range(6)),
                                     free=("x",))
    x = p.to_vector(p.initial())
    lo, hi = placement_lib.X_RANGE
    reach = scene.obstacles[0].reach
    self.assertLen(x, 6)
    np.testing.assert_allclose([x[0] - reach, x[-1] + reach], [lo, hi])
    # Three baffles asked at one place are pushed apart, inside the range.
    x[1:4] = 0.9
    repaired = p.to_vector(p.project(p.from_vector(x)))
    gaps = np.diff(np.sort(repaired))
    self.assertTrue(np.all(gaps >= 2 * reach - 1e-6), gaps)
    self.assertTrue(np.all((repaired >= lo) & (repaired <= hi)))
    p.check(p.from_vector(repaired))


if __name__ == "__main__":
  absltest.main()
