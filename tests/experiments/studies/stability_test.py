"""Tests for `experiments.studies.stability`: the frame checks on synthetic runs, and
one real case of each simulator through the table."""

import math
import os
import tempfile

from absl.testing import absltest
import numpy as np

import mpm
from experiments.studies import stability

# A floor 5 cm high with one block on it; sand is 1 cm apart.
SCENE = mpm.Scene.from_dict({
    "name": "checks", "domain": {"width": 0.4, "height": 0.3},
    "ramp": {"kind": "polyline", "points": [[0.0, 0.05], [0.4, 0.05]]},
    "obstacles": [{"shape": "rectangle", "x": 0.1, "width": 0.04,
                   "height": 0.04}],
    "granular": {"box": [0.25, 0.1, 0.35, 0.2], "spacing": 0.01},
    "num_frames": 5})


def _resting(frames=6, n=100):
  """[T, N, 2] sand at rest above the floor, away from the block."""
  rng = np.random.default_rng(0)
  x = rng.uniform([0.2, 0.07], [0.38, 0.2], (n, 2))
  return np.repeat(x[None], frames, 0)


class CheckFramesTest(absltest.TestCase):

  def test_a_physical_run_passes(self):
    check = stability.check_frames(_resting(), np.arange(6), SCENE)
    self.assertTrue(check.ok)
    self.assertEqual((check.max_inside, check.max_outside, check.max_speed,
                      check.final_speed), (0.0, 0.0, 0.0, 0.0))
    # Sand still creeping at the end (a deposit that never settles).
    x = _resting()
    x[-1] += [0.001, 0.0]
    check = stability.check_frames(x, np.arange(6), SCENE)
    self.assertAlmostEqual(check.final_speed, 0.001 / SCENE.frame_dt)
    # At rest from the first frame, until a last step at 0.4 m/s.
    self.assertEqual(check.rest_time, math.inf)
    self.assertEqual(stability.check_frames(_resting(), np.arange(6),
                                            SCENE).rest_time, 0.0)
    x = _resting(8)
    x[3:] += [0.0005, 0.0]     # moves in step 3 (0.2 m/s), then rests
    check = stability.check_frames(x, np.arange(8), SCENE)
    self.assertAlmostEqual(check.rest_time, 3 * SCENE.frame_dt)
    self.assertEqual(check.creep, 0.0)

  def test_each_break_is_found_at_its_first_frame(self):
    frames = np.arange(10, 16)   # stored frame numbers, not indices
    cases = []
    x = _resting(); x[3, 7] = np.nan
    cases.append((x, 13, "not finite"))
    x = _resting(); x[4:, 0] = [0.5, 0.1]            # 10 cm outside
    cases.append((x, 14, "1.0% of the sand outside the domain"))
    x = _resting(); x[2:, :3] = [0.3, 0.03]           # 2 cm into the floor
    cases.append((x, 12, "3.0% of the sand inside solids"))
    x = _resting(); x[:, 5] = [0.1, 0.07]             # inside the block
    x[:, 6] = [0.11, 0.06]
    cases.append((x, None, None))                     # 2%: allowed
    bound = stability.SPEED_MARGIN * math.sqrt(2 * 9.81 * 0.3)
    x = _resting(); x[5:, 9, 0] += 1.1 * bound * SCENE.frame_dt
    cases.append((x, 15, "above"))
    for x, frame, reason in cases:
      check = stability.check_frames(x, frames, SCENE)
      self.assertEqual(check.frame, frame, reason)
      if reason:
        self.assertIn(reason, check.reason)
    # The worst values are those of the finite frames.
    x = _resting(); x[2:, :3] = [0.3, 0.03]; x[4, 0] = np.inf
    check = stability.check_frames(x, frames, SCENE)
    self.assertEqual(check.frame, 12)
    self.assertAlmostEqual(check.max_inside, 0.03)

  def test_speed_uses_the_time_between_stored_frames(self):
    # Every third frame stored (a learned step of 3 frames): 3 frame times
    # between entries, so a move of 2 bounds' worth of one frame is slow.
    bound = stability.SPEED_MARGIN * math.sqrt(2 * 9.81 * 0.3)
    x = _resting()
    x[3:, 0, 0] += 2 * bound * SCENE.frame_dt
    self.assertTrue(stability.check_frames(x, np.arange(0, 18, 3),
                                           SCENE).ok)
    self.assertFalse(stability.check_frames(x, np.arange(6), SCENE).ok)


class CasesTest(absltest.TestCase):

  def test_every_mpm_case_builds(self):
    names = set()
    for case in stability.mpm_cases():
      self.assertNotIn(case.name, names)
      names.add(case.name)
      try:
        scene = case.scene()
      except mpm.InputError as e:
        self.fail(f"{case.name}: {e}")
      self.assertEqual(scene.num_frames, 600)
      # The grid follows the particle spacing (2 particles per cell side).
      self.assertAlmostEqual(scene.dx, 2 * scene.granular.spacing)

  def test_every_gns_case_builds_with_its_sand_above_the_ramp(self):
    for case in stability.gns_cases(0.01):
      try:
        scene = case.scene()
      except mpm.InputError as e:
        self.fail(f"{case.name}: {e}")
      sand = mpm.granular_particles(scene)
      self.assertBetween(len(sand), 100, 250, case.name)
      self.assertEqual(stability.metrics.inside_solids(sand[None], scene)[0],
                       0.0, case.name)

  def test_learned_rows_against_the_mpm(self):
    frames = np.arange(6)
    start = _resting(1)[0]
    mpm_run = _resting(6)
    mpm_run[1:] -= [0.2, 0.0]          # slides 20 cm, then rests
    learned = _resting(6)
    learned[1:] -= [0.1, 0.0]          # 10 cm, then creeps 1 mm per frame
    learned[1:] -= np.arange(5)[:, None, None] * [0.001, 0.0]
    row = stability.against_mpm(learned, mpm_run, start, frames, SCENE)
    self.assertEqual(row["mpm_final_speed_m_s"], 0.0)
    self.assertEqual(row["mpm_rest_time_s"], round(SCENE.frame_dt, 3))
    self.assertEqual(row["mpm_creep_mm_s"], 0.0)   # at rest: no drift
    self.assertAlmostEqual(row["travel_ratio"], 0.104 / 0.2, places=3)
    self.assertAlmostEqual(row["centre_travel_ratio"], 0.104 / 0.2,
                           places=3)
    self.assertEqual(set(row), set(stability.AGAINST_MPM))

  def test_a_sheet_that_leaves_the_bulk_behind(self):
    # Only the tenth of the sand furthest down the slope follows the MPM's
    # 20 cm: the front travels as far, the centre a tenth as far.
    frames = np.arange(6)
    start = _resting(1)[0]
    mpm_run = _resting(6)
    mpm_run[1:] -= [0.2, 0.0]
    learned = _resting(6)
    sheet = start[:, 0] <= np.quantile(start[:, 0], 0.1)
    learned[1:, sheet] -= [0.2, 0.0]
    row = stability.against_mpm(learned, mpm_run, start, frames, SCENE)
    self.assertAlmostEqual(row["travel_ratio"], 1.0, places=3)
    self.assertAlmostEqual(row["centre_travel_ratio"], sheet.mean(),
                           places=3)

  def test_rows_of_a_run_a_blow_up_and_a_refused_scene(self):
    outcome = stability.run_mpm(stability.Case("tiny", "mpm", "",
                                               lambda: SCENE))
    row = outcome.row
    self.assertEqual((row["status"], row["frames"], row["particles"]),
                     ("ok", 5, 100), row)
    with tempfile.TemporaryDirectory() as d:
      path = stability.picture(outcome, os.path.join(d, "tiny.png"))
      self.assertGreater(os.path.getsize(path), 1000)

    def blow_up(scene):
      raise mpm.SimulationError(scene.name, 3, "positions are not finite")

    real, mpm.simulate = mpm.simulate, blow_up
    try:
      row = stability.run_mpm(stability.Case("tiny", "mpm", "",
                                             lambda: SCENE)).row
    finally:
      mpm.simulate = real
    self.assertEqual((row["status"], row["frames"], row["break_frame"]),
                     ("broken", 3, 3))
    self.assertIn("scene 'tiny', frame 3: positions are not finite",
                  row["what"])

    def off_the_ramp():
      return stability._scene(obstacles=[{"shape": "semicircle", "x": 1.6,
                                          "radius": 0.05}])
    row = stability.run_mpm(stability.Case("off", "mpm", "",
                                           off_the_ramp)).row
    self.assertEqual(row["status"], "refused")
    self.assertIn("scene refused: ", row["what"])


if __name__ == "__main__":
  absltest.main()
