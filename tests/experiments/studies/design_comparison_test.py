"""Tests for `experiments.studies.design_comparison`: every method under one
budget on a tiny two-obstacle scene, judged and verified by the MPM; the
settings' refusals."""

import csv
import os
import tempfile

from absl.testing import absltest
import numpy as np

import mpm
from experiments.studies import design_comparison
from gnsjax.design import objectives
from gnsjax.design import placement as placement_lib
from tests.gnsjax.design.fixtures import TWO_OBSTACLES
from tests.gnsjax.design.fixtures import scene


class CompareTest(absltest.TestCase):

  def test_every_method_within_its_budget_and_verified(self):
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES,
                                           num_frames=12))
    out = tempfile.mkdtemp()
    settings = design_comparison.Settings(
        method=design_comparison.METHODS, budget_evals=4, learning_rate=0.01,
        sigma=0.01, num_samples=2, batch_size=2, sweep_points=2)
    summary = design_comparison.compare(settings, p, objectives.make("runout"),
                                        out)
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
    self.assertIn(summary["winner"], design_comparison.METHODS)
    with open(os.path.join(out, "report.md")) as f:
      report = f.read()
    self.assertIn("| cmaes | 4 |", report)
    self.assertIn("Budget per method: 4 evaluations", report)
    self.assertIn("load average", report)

  def test_step_scale_follows_the_ranges(self):
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES))
    s = design_comparison.step_scale(p, p.initial())
    np.testing.assert_allclose(s["x"], [1, 1])
    np.testing.assert_allclose(s["size"], np.full((2, 2), 0.03 / 0.8),
                               rtol=1e-5)



class SettingsTest(absltest.TestCase):

  def test_bad_settings_are_refused_naming_their_flags(self):
    ok = {"budget_s": 10.0}
    for changes, message in (
        ({}, "needs a budget; allowed: --budget_s > 0 and/or --budget_evals"),
        ({**ok, "method": ("adam", "nope")}, "^--method=adam,nope: allowed: "
         "one or more distinct of adam, adam_smoothed, cmaes, random, sweep"),
        ({**ok, "method": ("adam", "adam")}, "one or more distinct"),
        ({**ok, "num_samples": 3}, "^--num_samples=3; allowed: an even"),
        ({**ok, "problem": "baffles", "num_baffles": 9},
         "^--num_baffles=9; allowed: 2-8"),
        ({**ok, "xs": (1.0,)}, "^--xs=1: allowed: 2 comma-separated"),
        ({**ok, "xs": (1.0, 1.05)}, "the obstacles overlap; allowed: base "
         "centres at least 0.08 m apart"),
        ({**ok, "xs": (0.9, 1.5)}, "^--xs=0.9,1.5: obstacle 1 at x = 1.5; "
         r"allowed: \[0.5, 1.3\] m"),
        ({**ok, "radii": (0.04, 0.2)}, r"obstacle 1 of radius 0.2; allowed: "
         r"\[0.02, 0.05\] m"),
        ({**ok, "problem": "placement", "scene": "a.json"},
         "^--scene: the comparison of methods builds its scene"),
        ({**ok, "problem": "placement", "x0": 0.3},
         r"^--x0=0.3; allowed: \[0.5, 1.3\] m")):
      with self.assertRaisesRegex(mpm.InputError, message, msg=str(changes)):
        design_comparison.Settings(**changes)
    # What a problem does not read is not checked.
    design_comparison.Settings(**ok, problem="baffles", xs=(1.0, 1.05))
    design_comparison.Settings(**ok, x0=0.3)



if __name__ == "__main__":
  absltest.main()
