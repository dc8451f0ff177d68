"""Tests for `experiments.studies.calibration`: the settings' refusals, and
the study's files on a short rollout (the solver itself:
tests/gnsjax/design/calibration_test.py)."""

import csv
import os
import tempfile

from absl.testing import absltest
import pytest

import mpm
from experiments.studies import calibration


class CalibrationStudyTest(absltest.TestCase):

  def test_bad_settings_are_refused_naming_their_flags(self):
    ok = {"method": ("cmaes",), "budget_s": 10.0}
    for changes, message in (
        ({**ok, "truth": (60.0, 0.4)},
         r"^--truth: friction_angle_deg = 60: allowed range \[20, 50\]"),
        ({**ok, "start": (25.0,)}, "^--start=25: allowed: two numbers, the "
         "friction angle"),
        ({**ok, "method": ("adam_smoothed",)}, "allowed for "
         "--problem=calibrate: one or more of adam, cmaes, random, sweep"),
        ({"method": ("cmaes",)}, "needs a budget")):
      with self.assertRaisesRegex(mpm.InputError, message, msg=str(changes)):
        calibration.Settings(**changes)

  @pytest.mark.slow  # compiles the batched, the differentiated and the
  # plain rollout of 250 particles (two minutes on a busy 2-core machine)
  def test_run_writes_each_methods_trace_and_the_report(self):
    out = tempfile.mkdtemp()
    summary = calibration.run(calibration.Settings(
        method=("adam", "random"), budget_evals=2, batch_size=2,
        num_frames=6), out)
    for name in ("trace.csv", "summary.json", "report.md",
                 "objective_vs_time.png"):
      self.assertTrue(os.path.exists(os.path.join(out, name)), name)
    self.assertEqual([r["method"] for r in summary["runs"]],
                     ["adam", "random"])
    self.assertEqual([r["evaluations"] for r in summary["runs"]], [2, 2])
    self.assertEqual(summary["truth"], {"friction_angle_deg": 33.3,
                                        "basal_friction": 0.37})
    with open(os.path.join(out, "trace.csv")) as f:
      self.assertLen(list(csv.DictReader(f)), 4)
    with open(os.path.join(out, "report.md")) as f:
      text = f.read()
    self.assertIn("Budget per method: 2 evaluations", text)
    self.assertIn("| random | 2 |", text)


if __name__ == "__main__":
  absltest.main()
