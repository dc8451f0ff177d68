"""Tests for `gnsjax.metrics` against hand computations."""

import math

from absl.testing import absltest
import numpy as np

import mpm
from gnsjax import metrics

# A straight ramp y = 0.05 + 0.25 x (normal (-1, 4) / sqrt(17)), a semicircle
# of radius 0.03 m standing on it at x = 0.1, sand spacing 0.01 m.
SCENE = mpm.Scene.from_dict({
    "name": "metrics", "domain": {"width": 0.4, "height": 0.3},
    "ramp": {"kind": "polyline", "points": [[0.0, 0.05], [0.4, 0.15]]},
    "obstacles": [{"shape": "semicircle", "x": 0.1, "radius": 0.03}],
    "granular": {"box": [0.25, 0.2, 0.35, 0.28], "spacing": 0.01}})
RAMP_NORMAL = np.array([-1.0, 4.0]) / np.sqrt(17.0)


def on_ramp(x, depth):
  """A point ``depth`` (m) below the ramp surface at abscissa x."""
  return np.array([x, 0.05 + 0.25 * x]) - depth * RAMP_NORMAL


class MetricsTest(absltest.TestCase):

  def test_positional_mse_by_hand(self):
    true = np.zeros((2, 2, 2))
    pred = np.array([[[3.0, 4.0], [0.0, 0.0]],     # errors 25 and 0
                     [[1.0, 0.0], [0.0, 2.0]]])    # errors 1 and 4
    np.testing.assert_allclose(metrics.positional_mse(pred, true),
                               [12.5, 2.5])
    with self.assertRaisesRegex(ValueError, "shapes differ"):
      metrics.positional_mse(pred, true[:, :1])

  def test_runout_is_the_front(self):
    x = np.linspace(0.5, 1.5, 101)
    frame = np.stack([x, np.zeros_like(x)], -1)[None]
    np.testing.assert_allclose(metrics.runout(frame, 0.0), [0.5])
    np.testing.assert_allclose(metrics.runout(frame, 0.01), [0.51])
    shifted = frame + np.array([-0.2, 0.0])
    np.testing.assert_allclose(metrics.runout_error(shifted, frame), [0.2])

  def test_deposit_profile_and_error(self):
    true = np.array([[0.05, 0.1], [0.05, 0.3], [0.15, 0.2]])
    edges = np.array([0.0, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(metrics.deposit_profile(true, edges),
                               [0.3, 0.2, np.nan])
    self.assertEqual(metrics.deposit_error(true, true, 0.1), 0.0)
    # Bins of 0.1 m from the leftmost sand (0.05): one 0.1 m too high, the
    # other right, so RMS = 0.1 / sqrt(2).
    true = np.array([[0.05, 0.1], [0.05, 0.3], [0.2, 0.2]])
    pred = true + np.array([[0.0, 0.1], [0.0, 0.1], [0.0, 0.0]])
    np.testing.assert_allclose(metrics.deposit_error(pred, true, 0.1),
                               0.1 / np.sqrt(2), atol=1e-12)

  def test_solid_distance_by_hand(self):
    points = np.stack([on_ramp(0.3, 0.01), on_ramp(0.3, -0.002),
                       [0.1, 0.075 + 0.05]])   # 2 cm above the semicircle
    np.testing.assert_allclose(metrics.solid_distance(points, SCENE),
                               [-0.01, 0.002, 0.02], atol=1e-6)

  def test_inside_solids_by_hand(self):
    frame0 = np.stack([
        on_ramp(0.3, -0.01),        # 1 cm above the ramp: free
        on_ramp(0.3, 0.001),        # 1 mm in the ramp
        on_ramp(0.35, 0.01),        # 1 cm in the ramp
        [0.1, 0.075 + 0.01],        # 2 cm deep in the semicircle
    ])
    frame1 = frame0 + np.array([0.0, 0.2])    # all free
    positions = np.stack([frame0, frame1])
    # Default tolerance: half the spacing, 5 mm.
    np.testing.assert_allclose(metrics.inside_solids(positions, SCENE),
                               [0.5, 0.0])
    np.testing.assert_allclose(
        metrics.inside_solids(positions, SCENE, tolerance=5e-4), [0.75, 0.0])
    np.testing.assert_allclose(
        metrics.inside_solids(positions, SCENE, tolerance=0.015), [0.25, 0.0])

  def test_outside_domain_by_hand(self):
    # Domain [0, 0.4] x [0, 0.3]; the ramp does not count.
    frame = np.array([[-0.01, 0.2],     # 1 cm left of the domain
                      [0.2, 0.301],     # 1 mm above it
                      [0.41, 0.2],      # 1 cm right of it
                      [0.3, 0.05]])     # inside the ramp, in the domain
    positions = np.stack([frame, np.full_like(frame, 0.2)])
    np.testing.assert_allclose(metrics.outside_domain(positions, SCENE),
                               [0.5, 0.0])
    np.testing.assert_allclose(
        metrics.outside_domain(positions, SCENE, tolerance=5e-4), [0.75, 0.0])

  def test_front_error_relative_by_hand(self):
    x = np.linspace(1.0, 1.5, 101)
    start = np.stack([x, np.zeros_like(x)], -1)   # front (1% quantile) 1.005
    true = start - np.array([0.3, 0.0])           # travelled 0.3 m
    pred = start - np.array([0.24, 0.0])          # 0.06 m short of it
    self.assertAlmostEqual(metrics.front_error_relative(pred, true, start),
                           0.2, places=9)
    self.assertAlmostEqual(
        metrics.front_error_relative(true - [0.03, 0.0], true, start), 0.1,
        places=9)
    self.assertEqual(metrics.front_error_relative(true, true, start), 0.0)

  def test_final_speed_by_hand(self):
    # Particle 0 moves at (3, 4) cm per 7.5 ms step (6.67 m/s), particle 1
    # rests; steps before the last five do not count.
    times = 0.0075 * np.arange(8)
    x = np.zeros((8, 2, 2))
    x[:, 0] = np.arange(8)[:, None] * [0.03, 0.04]
    x[:2, 1] = [[1.0, 1.0], [2.0, 0.0]]
    self.assertAlmostEqual(metrics.final_speed(x, times), 0.05 / 0.0075 / 2)
    self.assertEqual(metrics.final_speed(x[:, 1:], times), 0.0)
    with self.assertRaisesRegex(ValueError, "need as many"):
      metrics.final_speed(x, times[:-1])

  def test_rest_targets_by_hand(self):
    # The MPM's sand at 0 / 4 mm/s / 2 cm/s: the bound is the 1 cm/s
    # floor, the floor again (8 mm/s < 1 cm/s), then twice the MPM's.
    mpm = np.array([0.0, 0.004, 0.02])
    np.testing.assert_allclose(metrics.rest_speed_bound(mpm),
                               [0.01, 0.01, 0.04])
    self.assertEqual(float(metrics.rest_speed_bound(0.02, floor=0.05)), 0.05)
    over_speed, over_energy = metrics.over_rest_targets(
        [0.0099, 0.0101, 0.04], mpm, [10.0, 10.5, 0.1])
    np.testing.assert_array_equal(over_speed, [False, True, False])
    np.testing.assert_array_equal(over_energy, [False, True, False])
    over_speed, over_energy = metrics.over_rest_targets(0.05, 0.02, 11.0)
    self.assertTrue(over_speed)
    self.assertTrue(over_energy)

  def test_paired_difference_by_hand(self):
    # Differences 1, 3 (mean 2, sample std sqrt(2)) on a mean of 4.
    # The standard error: sqrt(2) / sqrt(2) = 1; twice it, 50% of 4.
    mean, two_se = metrics.paired_difference([4.0, 8.0], [3.0, 5.0])
    self.assertAlmostEqual(mean, 50.0)
    self.assertAlmostEqual(two_se, 50.0)
    # The pairing counts: scenes that differ a lot between each other but
    # not between the models give a small error.
    # (Unpaired, the scenes' own spread would make it about 170%.)
    b = np.array([1.0, 10.0, 100.0, 1000.0])
    mean, two_se = metrics.paired_difference(b + [2.0, 3.0, 2.0, 3.0], b)
    self.assertAlmostEqual(mean, 100 * 2.5 / np.mean(b))
    self.assertLess(two_se, 0.25)
    with self.assertRaisesRegex(ValueError, "S >= 2"):
      metrics.paired_difference([1.0], [2.0])

  def test_rest_metrics_by_hand(self):
    # 3 particles: moving at 0.1 m/s in x until t = 0.5 s, then at rest
    # except particle 0, which creeps at 1 mm/s.
    times = np.round(np.arange(21) * 0.05, 10)
    v = np.where(times <= 0.5, 0.1, 0.0)      # over the step ending then
    x = np.zeros((len(times), 3, 2))
    x[:, :, 0] = np.concatenate([[0.0], np.cumsum(v[1:] * 0.05)])[:, None]
    x[:, 0, 0] += np.where(times > 0.5, (times - 0.5) * 0.001, 0.0)
    self.assertAlmostEqual(metrics.rest_time(x, times, speed=0.01), 0.5)
    self.assertEqual(metrics.rest_time(x, times, speed=1e-5), math.inf)
    self.assertAlmostEqual(metrics.creep(x, times, since=0.5), 0.001 / 3)
    # Over the last 0.25 s only the creeping particle moves.
    self.assertAlmostEqual(metrics.specific_kinetic_energy(x, times, 0.25),
                           0.5 * 0.001**2 / 3)
    # Moving throughout at 0.1 m/s: 5e-3 J/kg.
    moving = x.copy()
    moving[:, :, 0] = times[:, None] * 0.1
    self.assertAlmostEqual(
        metrics.specific_kinetic_energy(moving, times, 0.25), 5e-3)
    self.assertAlmostEqual(metrics.kinetic_energy_ratio(
        moving, x, times, times), 5e-3 / (0.5 * 0.001**2 / 3))
    # Truth exactly at rest: the floor keeps the ratio finite.
    still = np.zeros_like(x)
    self.assertAlmostEqual(metrics.kinetic_energy_ratio(
        moving, still, times, times, floor=1e-6), 5e-3 / 1e-6)

  def test_constant_velocity_by_hand(self):
    # x = t^2 at frame t: the velocity changes, the baseline does not.
    t = np.arange(12.0)
    positions = np.stack([t**2, -t], -1)[:, None, :]          # [F, 1, 2]
    # C = 3, k = 2: inputs 0, 2, 4; velocity (16 - 4) / 2 = 6 per frame.
    got = metrics.constant_velocity(positions, np.array([6, 8]), 3, 2)
    np.testing.assert_allclose(got[:, 0], [[16 + 12, -6], [16 + 24, -8]])
    # C = 3, k = 1: inputs 0, 1, 2; velocity 4 - 1 = 3.
    got = metrics.constant_velocity(positions, np.array([3, 4, 5]), 3)
    self.assertEqual(got.shape, (3, 1, 2))
    np.testing.assert_allclose(got[:, 0], [[7, -3], [10, -4], [13, -5]])


if __name__ == "__main__":
  absltest.main()
