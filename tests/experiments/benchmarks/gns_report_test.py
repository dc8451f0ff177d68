"""Tests for `experiments.benchmarks.gns_report` (the peers' quoted times)."""

import os

from absl.testing import absltest

from experiments.benchmarks import gns_report
from tests.experiments.benchmarks import fixtures


class QuotesTest(absltest.TestCase):

  def test_readme_quoting_the_peers_is_checked(self):
    d = fixtures.tempdir(self)
    fixtures.write_sand_block(d)
    readme = os.path.join(d, "README.md")
    self.assertEqual(gns_report.check_quotes(readme),
                     {"quoted_from": readme, "readme_checked": True})

  def test_readme_with_other_figures_is_refused(self):
    readme = os.path.join(fixtures.tempdir(self), "README.md")
    with open(readme, "w") as f:
      f.write("geoelements/gns 0.50 s and 1.53 s")
    with self.assertRaisesRegex(ValueError, "0.54 s"):
      gns_report.check_quotes(readme)

  def test_missing_readme_is_recorded_not_fatal(self):
    readme = os.path.join(fixtures.tempdir(self), "README.md")
    self.assertFalse(gns_report.check_quotes(readme)["readme_checked"])

  def test_peers_are_compared_with_the_quoted_times(self):
    row = {"forward": {"median_s": 0.27, "min_s": 0.27},
           "train_step": {"median_s": 1.53, "min_s": 1.0}}
    out = gns_report.compare_peers(row, {"quoted_from": "README.md",
                                         "readme_checked": True})
    ref = out["peers"][gns_report.REFERENCE_PEER]
    self.assertAlmostEqual(ref["forward_ratio"], 0.5)
    self.assertAlmostEqual(ref["train_step_ratio"], 1.0)
    self.assertTrue(out["forward_target_met"])
    self.assertFalse(out["train_step_target_met"])
    self.assertEqual(out["quoted_from"], "README.md")


class InputLayerNoteTest(absltest.TestCase):

  def test_note_names_the_features_and_the_previous_count(self):
    scene = {"n_node_features": 13, "sdf_scene": "paper_semicircle",
             "sdf_spacing": 0.0025}
    note = gns_report.input_layer_note(
        {"scenes": {"sand_block": scene, "paper_scene": scene}})
    self.assertIn("Node features: 13", note)
    self.assertIn("paper_semicircle's at 2.5 mm", note)
    self.assertIn("had 14", note)

  def test_results_from_before_the_sdf_features(self):
    note = gns_report.input_layer_note({"scenes": {"sand_block": {}}})
    self.assertIn("Node features: 14", note)


if __name__ == "__main__":
  absltest.main()
