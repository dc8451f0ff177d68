"""Tests for `experiments.studies.gradient_check`: the report's table and
sign counts, the range checks, and the study's files on a short rollout."""

import json
import os
import tempfile

from absl.testing import absltest
import pytest

import mpm
from experiments.studies import gradient_check
from gnsjax.design import objectives
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from tests.gnsjax.design.fixtures import scene


def _mpm_driver(s: mpm.Scene) -> rollouts.MPMDriver:
  return rollouts.MPMDriver(rollouts.MPMRollout.create(
      placement_lib.Placement(s)))


class GradientCheckTest(absltest.TestCase):

  def test_report_counts_sign_agreements_with_the_slope(self):
    row = {"x": 1.0, "sigma": 0.05, "num_samples": 4, "slope_smooth": 0.3,
           "slope_plain": 0.25, "pathwise": -5.8, "pathwise_s": 1.0,
           "smoothed_pathwise": 0.2, "smoothed_pathwise_stderr": 0.1,
           "smoothed_pathwise_s": 2.0, "smoothed_score": -0.1,
           "smoothed_score_stderr": 0.3, "smoothed_score_s": 1.5}
    text = gradient_check.report([row, dict(row, x=0.8, pathwise=0.1)], "t")
    self.assertIn("pathwise 1/2, smoothed_pathwise 2/2, smoothed_score 0/2",
                  text)
    self.assertIn("| 1.00 | 0.3 / 0.25 | -5.8 | 0.2 +- 0.1 |", text)
    text = gradient_check.report([{**row, "difference_h0.001": 1.5}], "t")
    self.assertIn("| differences, h = 0.001 m | jax.grad |", text)
    self.assertIn("| 1.00 | 0.3 / 0.25 | 1.5 | -5.8 |", text)

  def test_positions_whose_interval_leaves_the_range_are_refused(self):
    with self.assertRaisesRegex(ValueError, r"x = 1.28 m: x \+- sigma"):
      gradient_check.check(_mpm_driver(scene()),
                           objectives.make("runout"), [1.28], sigma=0.05,
                           num_samples=2)

  def test_settings_refuse_positions_too_near_the_ends(self):
    for changes, message in (
        ({"xs": (0.52,)}, r"^--xs: \[0.52\] with --sigma=0.05: x \+- sigma "
         r"must lie in \[0.5, 1.3\] m"),
        ({"xs": (0.8,), "hs": (0.4,)}, r"^--xs: \[0.8\] with --hs: x \+- h"),
        ({"hs": (0.0,)}, r"^--hs=0.0: allowed: > 0"),
        ({"num_samples": 3}, "^--num_samples=3; allowed: an even number")):
      with self.assertRaisesRegex(mpm.InputError, message, msg=str(changes)):
        gradient_check.Settings(**changes)

  @pytest.mark.slow  # compiles the rollout, its gradient and both smoothed
  # gradients of 250 particles (three minutes on a busy 2-core machine)
  def test_run_writes_rows_summary_and_report(self):
    out = tempfile.mkdtemp()
    summary = gradient_check.run(gradient_check.Settings(
        xs=(1.0,), num_samples=2, num_frames=4, hs=(0.01,),
        objective="runout"), out)
    for name in ("rows.csv", "summary.json", "report.md"):
      self.assertTrue(os.path.exists(os.path.join(out, name)), name)
    with open(os.path.join(out, "summary.json")) as f:
      written = json.load(f)
    self.assertEqual(written["simulator"], "mpm")
    self.assertIsNone(written["workdir"])
    (row,) = summary["rows"]
    self.assertEqual(row["x"], 1.0)
    self.assertIn("difference_h0.01", row)
    with open(os.path.join(out, "report.md")) as f:
      self.assertIn("Gradient check (MPM): runout, design_semicircle, 4 "
                    "frames", f.read())


if __name__ == "__main__":
  absltest.main()
