"""Tests for `experiments.studies.convergence`: the extrapolation, the
runouts, the column scene, the settings' refusals, ``run`` on a tiny case,
and the MPM's convergence at coarse resolutions."""

import functools
import json
import math
import os
import tempfile

from absl.testing import absltest
import numpy as np
import pytest

import mpm
from experiments.studies import convergence


class ConvergenceTest(absltest.TestCase):

  def test_richardson_recovers_a_first_and_a_second_order_limit(self):
    for order in (1, 2):
      h = np.array([0.4, 0.2, 0.1])
      value, got = convergence.richardson(list(1.5 - 0.7 * h**order))
      self.assertAlmostEqual(value, 1.5, places=12)
      self.assertAlmostEqual(got, order, places=12)

  def test_richardson_refuses_changes_that_do_not_shrink(self):
    for values in ([0.6, 0.8, 1.1], [0.6, 0.8, 0.7], [0.6, 0.6, 0.6]):
      value, order = convergence.richardson(values)
      self.assertTrue(np.isnan(value) and np.isnan(order), values)

  def test_runouts_of_a_final_deposit(self):
    x = np.linspace(0.0, 0.3, 1001)    # a deposit reaching 0.3 m
    r = convergence.runouts(x, width0=0.1)
    self.assertEqual(list(r), [n for n, _ in convergence.MEASURES])
    self.assertAlmostEqual(r["runout_front"], 2.0)
    self.assertAlmostEqual(r["runout_q995"], (0.995 * 0.3 - 0.1) / 0.1)
    self.assertAlmostEqual(r["runout_q90"], (0.9 * 0.3 - 0.1) / 0.1)
    # Mean x 0.15 m against the column's own 0.05 m.
    self.assertAlmostEqual(r["centre"], (0.15 - 0.05) / 0.1)

  def test_paper_measures_are_distances_travelled_downhill(self):
    start = np.linspace(1.0, 1.5, 1001)
    end = np.linspace(0.2, 1.2, 1001)    # the sand runs towards x = 0
    m = convergence.paper_measures(start, end)
    self.assertAlmostEqual(m["front_travel_m"], 0.8)
    self.assertAlmostEqual(m["front_q01_travel_m"], 1.005 - 0.21)
    self.assertAlmostEqual(m["front_q10_travel_m"], 1.05 - 0.3)
    self.assertAlmostEqual(m["mean_travel_m"], 1.25 - 0.7)

  def test_extrapolation_lines(self):
    h = np.array([0.01, 0.005, 0.0025])
    rows = [{"a": 1.0, "spacing_m": s, "conv": 2.0 - 8 * s,
             "div": 1.0 / s, "slow": slow}
            for s, slow in zip(h, (1.0, 1.5, 1.97))]
    lines = convergence.extrapolations(rows, "a", ["conv", "div", "slow"])
    # 2 - 8 h at h = 5 mm is 1.96: 2% from the limit 2.
    self.assertEqual(lines[0], "- a 1, conv (changes +0.04, +0.02): "
                     "Richardson 2 (order 1.00); the default spacing's value "
                     "is 2.0% from it, the finest's 1.0%")
    self.assertEqual(lines[1], "- a 1, div (changes +100, +200): Richardson "
                     "undefined: the changes do not shrink")
    # 0.5 then 0.47: order 0.09, a "limit" 16 changes away; not reported.
    self.assertEqual(lines[2], "- a 1, slow (changes +0.5, +0.47): the "
                     "changes shrink too slowly (order 0.09) for an "
                     "extrapolation to mean anything")
    table = convergence.markdown_table(rows)
    self.assertEqual(table[0], "| a | spacing_m | conv | div | slow |")
    self.assertEqual(table[2], "| 1 | 0.01 | 1.92 | 100 | 1 |")

  def test_column_scene(self):
    scene = convergence.column_scene(2.0, 0.005, height=0.1)
    np.testing.assert_allclose(scene.granular.box, (0.0, 0.02, 0.05, 0.12))
    self.assertAlmostEqual(scene.dx, 0.01)
    self.assertEqual(scene.wall_friction, 0.0)
    self.assertAlmostEqual(scene.boundary_friction, 0.7)
    # The column is filled: (0.05 / 0.005) x (0.1 / 0.005) particles.
    self.assertLen(mpm.granular_particles(scene), 10 * 20)


class SettingsTest(absltest.TestCase):

  def test_bad_settings_name_their_flags(self):
    convergence.Settings()
    bad = [({"height": 0.0}, "--height=0.0: allowed: > 0"),
           ({"time": -1.0}, "--time=-1.0: allowed: > 0"),
           ({"time": 0.02}, "--time=0.02: 8 frames of 2.5 ms; allowed: >= "
            "0.0275 s"),
           ({"aspect_ratios": (math.nan,)},
            "--aspect_ratios=nan: allowed: a finite number"),
           ({"cfl": 1.5}, "--cfl=1.5: allowed: <= 1"),
           ({"spacings": (0.0025, 0.005)}, "--spacings=0.0025,0.005; "
            "allowed: distinct spacings, coarse to fine"),
           ({"spacings": (0.03, 0.01)}, "--spacings=0.03: too coarse for "
            "the column of --height=0.1 and --aspect_ratios=1"),
           ({"aspect_ratios": (40.0,)}, "--spacings=0.005: too coarse for "
            r"the column of --height=0.1 and --aspect_ratios=40 \(0.0025 m "
            r"wide\); allowed: <= 0.0025 m"),
           ({"paper_scenes": (0, 100)}, "--paper_scenes=100: allowed: <= 99"),
           ({"paper_scenes": (1,), "paper_spacings": (0.2, 0.01)},
            "--paper_spacings=0.2: scene test/00001/semicircle "
            r"\(--paper_scenes=1\) is refused at this spacing: solver.dx"),
           ({"rheologies": ("mu_i_regularized",)},
            "--rheologies=mu_i_regularized with --friction_angle = 45: "
            "material: mu\\(I\\) with mu_s = 0.707.* is ill-posed at every "
            "inertial number"),
           ({"rheologies": ("mu_i_regularized",), "friction_angle": 22.5,
             "paper_scenes": (0,)},
            "--rheologies=mu_i_regularized with the paper scenes' friction "
            "angle = 35")]
    for changes, message in bad:
      with self.assertRaisesRegex(mpm.InputError, "^" + message,
                                  msg=str(changes)):
        convergence.Settings(**changes)
    # No column: the paper scenes alone.
    convergence.Settings(aspect_ratios=(), paper_scenes=(0,))


class RunTest(absltest.TestCase):

  def test_one_column_and_one_paper_scene(self):
    s = convergence.Settings(spacings=(0.02,), time=0.03, paper_scenes=(0,),
                             paper_spacings=(0.04,))
    with tempfile.TemporaryDirectory() as d:
      summary = convergence.run(s, d)
      self.assertCountEqual(os.listdir(d), [
          "convergence.csv", "convergence_paper.csv", "convergence.md",
          "deposits.png", "environment.json"])
      with open(os.path.join(d, "convergence.md")) as f:
        self.assertEqual(f.read(), convergence.report(summary))
      with open(os.path.join(d, "environment.json")) as f:
        self.assertEqual(json.load(f)["settings"], s.to_dict())
    (column,), (paper,) = summary["column"], summary["paper"]
    self.assertEqual((column["aspect_ratio"], column["spacing_m"],
                      column["particles"]), (1.0, 0.02, 25))
    self.assertEqual((paper["scene"], paper["dx_m"]), ("test/00000/none",
                                                       0.08))
    self.assertGreater(paper["front_travel_m"], 0.5)
    json.dumps(summary)
    self.assertIn("Settings: `{", convergence.report(summary))


# Spacings (m) of the coarse-resolution check: 1, 4 and 16 particles per
# 2 x 2 cm cell of the coarsest grid; 100, 400 and 1600 particles.
_COARSE = (0.01, 0.005, 0.0025)


@functools.lru_cache(maxsize=None)
def _coarse_runouts(aspect=1.0):
  """Runouts of the column at ``_COARSE`` spacings, after 0.5 s (the sand
  stops by 0.35 s)."""
  out = []
  for spacing in _COARSE:
    scene = convergence.column_scene(aspect, spacing, duration=0.5)
    x = np.asarray(mpm.simulate(scene).positions)[-1, :, 0]
    out.append(convergence.runouts(x, 0.1 / aspect))
  return out


def _change_ratio(runs, key):
  a, b, c = (r[key] for r in runs)
  return (c - b) / (b - a)


class CoarseConvergenceTest(absltest.TestCase):
  """The column at 10 / 5 / 2.5 mm spacings (2 / 1 / 0.5 cm grids)."""

  def test_the_bulk_of_the_deposit_converges(self):
    # Measured: the second change of the centre of mass is 0.52 of the
    # first, the 90% runout's 0.55 (the front's 1.39); losing convergence (a
    # change that stops shrinking) fails this.
    runs = _coarse_runouts()
    for key, most in (("centre", 0.75), ("runout_q90", 0.8)):
      ratio = _change_ratio(runs, key)
      self.assertTrue(0 < ratio <= most, f"{key}: {[r[key] for r in runs]}")

  @pytest.mark.xfail(strict=True, reason=(
      "solver: the deposit's front (its furthest particle) is not "
      "converged: the toe ends where the layer is 1.3-2 grid cells thick at "
      "every resolution, so it lengthens at each halving, by more each time "
      "(docs/physics.md). The target: changes that halve."))
  def test_the_front_converges_at_first_order(self):
    ratio = _change_ratio(_coarse_runouts(), "runout_front")
    self.assertTrue(0 < ratio <= 0.5, ratio)


if __name__ == "__main__":
  absltest.main()
