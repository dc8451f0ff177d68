"""Tests for `mpm.resolution`: the spacing a front tolerance needs, from the
shipped table of the speed/accuracy study."""

import json
import os

from absl.testing import absltest
import numpy as np

import mpm
from mpm import resolution

REPO = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))
STUDY = os.path.join(REPO, "docs", "results", "tradeoff", "tradeoff.json")


def _row(point, scene, obstacles, shapes, front):
  return {"point": point, "scene": scene, "obstacles": obstacles,
          "shapes": shapes, "front_error": front}


# The reference (2.5 mm) and three measured spacings on two scenes.
TABLE = {
    "reference": {"name": "mpm_0.0025"},
    "points": [
        {"name": "mpm_0.0025", "kind": "mpm", "spacing": 0.0025,
         "seconds": 11.0},
        {"name": "mpm_0.01", "kind": "mpm", "spacing": 0.01, "seconds": 0.2},
        {"name": "mpm_0.005", "kind": "mpm", "spacing": 0.005,
         "seconds": 1.5},
        {"name": "mpm_0.0035", "kind": "mpm", "spacing": 0.0035,
         "seconds": 4.0},
        {"name": "gns", "kind": "gns", "spacing": None, "seconds": 0.01},
    ],
    "rows": [
        _row("mpm_0.0025", "a", 0, [], 0.0),
        _row("mpm_0.0025", "b", 1, ["triangle"], 0.0),
        _row("mpm_0.01", "a", 0, [], 0.08),
        _row("mpm_0.01", "b", 1, ["triangle"], 0.30),
        _row("mpm_0.005", "a", 0, [], 0.05),
        _row("mpm_0.005", "b", 1, ["triangle"], 0.09),
        _row("mpm_0.0035", "a", 0, [], 0.03),
        _row("mpm_0.0035", "b", 1, ["triangle"], 0.04),
        _row("gns", "a", 0, [], 0.001), _row("gns", "b", 1, ["triangle"], 0.001),
    ],
}


def _scene(shapes=()):
  return mpm.sample_scene(0, num_obstacles=len(shapes),
                          shapes=tuple(shapes) or ("rectangle",))


class ChooseTest(absltest.TestCase):

  def test_the_cheapest_spacing_that_meets_the_tolerance_on_alike_scenes(self):
    plain, triangle = _scene(), _scene(["triangle"])
    self.assertEqual(resolution.choose(plain, 0.1, TABLE).spacing, 0.01)
    self.assertEqual(resolution.choose(triangle, 0.1, TABLE).spacing, 0.005)
    self.assertEqual(resolution.choose(triangle, 0.05, TABLE).spacing, 0.0035)
    chosen = resolution.choose(triangle, 0.1, TABLE)
    self.assertEqual(chosen.choice.scenes, ("b",))
    self.assertIn("5 mm", chosen.reason)
    self.assertIn("9.0%", chosen.reason)
    self.assertIn("with these obstacles", chosen.reason)
    # A scene unlike every study scene: the worst over all of them.
    two = _scene(["rectangle", "semicircle"])
    self.assertEqual(resolution.choose(two, 0.1, TABLE).spacing, 0.005)
    self.assertIn("none has these obstacles",
                  resolution.choose(two, 0.1, TABLE).reason)

  def test_neither_the_reference_nor_a_learned_simulator_is_chosen(self):
    # Only they "meet" 1%: the reference by definition, the GNS by its row.
    with self.assertRaisesRegex(
        mpm.InputError, r"front_tolerance = 0.01: .* the most accurate, "
        r"mpm_0.0035, reaches 0.03"):
      resolution.choose(_scene(), 0.01, TABLE)

  def test_bad_tolerances_are_refused(self):
    for bad in (0.0, -0.1, float("nan"), float("inf")):
      with self.assertRaisesRegex(mpm.InputError, "allowed: a finite number"):
        resolution.choose(_scene(), bad, TABLE)

  def test_at_spacing_keeps_the_sand_area_and_the_grid_rule(self):
    scene = _scene()
    coarse = resolution.at_spacing(scene, 0.01)
    self.assertEqual(coarse.granular.spacing, 0.01)
    self.assertEqual(coarse.dx, 0.02)
    np.testing.assert_allclose(
        coarse.granular.num_particles * 0.01**2,
        scene.granular.num_particles * scene.granular.spacing**2, rtol=0.01)
    self.assertEqual(coarse.obstacles, scene.obstacles)

  def test_the_shipped_table_is_the_committed_studys(self):
    shipped = resolution.load(resolution.FRONT_TABLE)
    study = resolution.mpm_table(resolution.load(STUDY))
    self.assertEqual(shipped, json.loads(json.dumps(study)))
    self.assertNotIn(study["reference"]["name"],
                     [p["name"] for p in shipped["points"]])


class SimulateTest(absltest.TestCase):

  def test_simulate_runs_the_scene_at_the_chosen_spacing(self):
    scene = mpm.sample_scene(0, num_particles=400, num_frames=3)
    result = mpm.simulate(scene, front_tolerance=0.5)
    chosen = resolution.choose(scene, 0.5)
    self.assertEqual(result.resolution, chosen)
    self.assertEqual(result.scene.granular.spacing, chosen.spacing)
    self.assertEqual(result.positions.shape[1],
                     len(mpm.granular_particles(result.scene)))
    self.assertIsNone(mpm.simulate(scene).resolution)


if __name__ == "__main__":
  absltest.main()
