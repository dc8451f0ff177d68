"""Tests for `experiments.studies.ablation`: the variants are cumulative
changes of the small config ending at its recipe, the settings refuse what
cannot run, and the table shows every row."""

from absl.testing import absltest

import mpm
from experiments.configs import small
from experiments.studies import ablation


class AblationTest(absltest.TestCase):

  def test_the_variants_change_the_small_config_and_end_at_its_recipe(self):
    config = small.get_config()
    recipe = small.get_config()
    for _, changes in ablation.ABLATION:
      for key, value in changes.items():
        section, field = key.split(".")
        self.assertIn(field, config[section], key)
        config[section][field] = value
    # Every part added, the last variant is the shipped recipe.
    self.assertEqual(config.model.to_dict(), recipe.model.to_dict())
    for key in ("frame_stride", "noise_velocity_fraction", "fold_noise",
                "motion_weighting"):
      self.assertEqual(config.train[key], recipe.train[key], key)
    self.assertEqual(ablation.VARIANTS[0], "previous")

  def test_settings_refusals_name_the_flag(self):
    ablation.Settings(data="data", variants=("stride3", "pushforward"))
    for changes, message in (
        ({"data": None}, "--data is required"),
        ({"minutes": 0.0}, "--minutes=0.0: allowed: > 0"),
        ({"variants": ("previous", "nope")},
         r"--variants=nope: allowed: one of \['previous', 'stride3'"),
        ({"variants": ()}, "--variants is empty"),
        ({"max_trajectories": 0}, "--max_trajectories=0: allowed: >= 1")):
      with self.assertRaisesRegex(mpm.InputError, "^" + message,
                                  msg=str(changes)):
        ablation.Settings(**({"data": "data"} | changes))

  def test_report(self):
    row = {"variant": "stride3", "steps": 120, "mean_mse": 1.5e-4,
           "mean_mse_constant_velocity": 3e-3,
           "median_front_error_relative": 0.125,
           "median_deposit_error": 0.0123, "max_inside_solids": 0.01,
           "max_outside_domain": 0.0, "mean_pushed_fraction": 0.0234}
    text = ablation.report({"rows": [row, row | {
        "variant": "pushforward", "free_max_inside_solids": 0.2}]})
    lines = text.splitlines()
    self.assertLen(lines, 4)
    self.assertEqual(lines[2], "| stride3 | 120 | 1.50e-04 | 3.00e-03 | "
                     "12.5% | 0.0123 | 1.0% | nan% | 0.0% | 2.34% |")
    self.assertIn("| 1.0% | 20.0% | 0.0% |", lines[3])


if __name__ == "__main__":
  absltest.main()
