"""Tests for `experiments.studies.validation`: the deposit's measures, the
power-law fit, the settings' refusals and ``run`` on a tiny case."""

import json
import math
import os
import tempfile

from absl.testing import absltest
import numpy as np

import mpm
from experiments.studies import convergence
from experiments.studies import validation
from mpm import incline


def _heap(width0, top, angle_deg, spacing):
  """Particles filling a trapezoid: flat top ``top`` (m) over [0, width0],
  a flank at ``angle_deg`` down to the floor."""
  run = top / math.tan(math.radians(angle_deg))
  xs = np.arange(spacing / 2, width0 + run, spacing)
  ys = np.arange(spacing / 2, top, spacing)
  x, y = np.meshgrid(xs, ys)
  height = np.where(x <= width0, top, top - (x - width0) * top / run)
  keep = y <= height
  return np.stack([x[keep], y[keep] + convergence.FLOOR], -1)


class MeasuresTest(absltest.TestCase):

  def test_a_heap_of_known_shape(self):
    x = _heap(0.1, 0.05, 30.0, 0.001)
    m = validation.column_measures(x, 1.0, 0.1, 0.001)
    self.assertAlmostEqual(m["flank_angle_deg"], 30.0, delta=1.0)
    self.assertAlmostEqual(m["height_over_L0"], 0.5, delta=0.01)
    self.assertAlmostEqual(m["h0_over_h"], 2.0, delta=0.05)
    # The 99.5% quantile of x lies near the toe, 0.1 + 0.087 m.
    self.assertAlmostEqual(m["runout"], 0.75, delta=0.05)

  def test_exponent_of_a_power_law(self):
    a = [0.5, 1, 2, 4, 8]
    # Only the tall columns count: the short ones follow another law.
    values = [100.0, 100.0] + [1.9 * x**(2 / 3) for x in a[2:]]
    self.assertAlmostEqual(validation.exponent(a, values), 2 / 3, places=6)
    self.assertTrue(math.isnan(validation.exponent([0.5, 1, 2], [1, 2, 3])))

  def test_bagnold_surface_is_the_mean_of_the_top_tenth(self):
    m = incline.strip_scene(0.02, material={"rheology": "mu_i"}).material
    theta = math.radians(34.0)
    top = validation.bagnold_surface(0.02, theta, m)
    self.assertLess(incline.bagnold_velocity(0.018, 0.02, theta, m), top)
    self.assertLess(top, incline.bagnold_velocity(0.02, 0.02, theta, m))


class SettingsTest(absltest.TestCase):

  def test_bad_settings_name_their_flags(self):
    validation.Settings()
    bad = [({"aspect_ratios": (), "incline_angles": ()},
            "--aspect_ratios and --incline_angles are both empty"),
           ({"rheologies": ("mu_i", "mu_i")}, "--rheologies=mu_i,mu_i"),
           ({"incline_angles": (95.0,)}, "--incline_angles=95.0: allowed: "
            "<= 90"),
           ({"incline_depth": 0.002}, "--incline_depth=0.002 with "
            "--incline_dx=0.001: the strip is refused: depth"),
           ({"spacing": 0.2}, "--aspect_ratios=0.5 with --spacing=0.2"),
           ({"grain_diameter": 0.0}, "--grain_diameter=0.0: allowed: > 0")]
    for changes, message in bad:
      with self.assertRaisesRegex(mpm.InputError, "^" + message,
                                  msg=str(changes)):
        validation.Settings(**changes)


class RunTest(absltest.TestCase):

  def test_one_column_and_one_incline(self):
    s = validation.Settings(aspect_ratios=(1.0,), spacing=0.02, time=0.05,
                            incline_angles=(34.0,), incline_depth=0.004,
                            incline_time=0.1)
    with tempfile.TemporaryDirectory() as d:
      summary = validation.run(s, d)
      self.assertCountEqual(os.listdir(d), [
          "validation.md", "column.csv", "incline.csv", "column.png",
          "incline.png", "environment.json"])
      with open(os.path.join(d, "validation.md")) as f:
        self.assertEqual(f.read(), validation.report(summary))
      with open(os.path.join(d, "environment.json")) as f:
        self.assertEqual(json.load(f)["settings"], s.to_dict())
    self.assertEqual([(r["rheology"], r["aspect_ratio"])
                      for r in summary["column"]],
                     [("drucker_prager", 1.0), ("mu_i", 1.0)])
    self.assertEqual(summary["column"][0]["lube_band"], "0.96-1.44")
    dp, mu_i = summary["incline"]
    self.assertNotIn("ratio", dp)                 # no steady state to match
    self.assertAlmostEqual(mu_i["inertial_number"], 0.177, places=3)
    self.assertGreater(mu_i["bagnold_surface_speed"], 0)
    # Both start from rest and gain speed down the slope.
    self.assertGreater(dp["surface_speed"], 0)
    self.assertGreater(mu_i["surface_speed"], 0)
    json.dumps(summary)


if __name__ == "__main__":
  absltest.main()
