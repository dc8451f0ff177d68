"""Calibration of the sand's friction from an observed deposit."""

from absl.testing import absltest
import jax.numpy as jnp
import numpy as np

import mpm
from gnsjax.design import baselines
from gnsjax.design import calibration

# 120 particles at 0.02 m released high on the ramp, 200 frames (0.5 s).
SCENE = mpm.Scene.from_dict({
    "name": "calibration_test", "obstacles": [],
    "granular": {"box": [1.2, 0.45, 1.45, 1.1], "spacing": 0.02,
                 "num_particles": 120}})
TRUTH = (35.0, 0.4)
START = (25.0, 0.8)


class CalibrationTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.problem = calibration.Calibration.observe(SCENE, TRUTH,
                                                  num_frames=200)

  def test_mass_distribution_by_hand(self):
    x = jnp.array([[0.5, 0.1], [0.7, 0.3]])
    got = calibration.mass_distribution(x, jnp.array([0.5, 0.6]), 0.1)
    g = lambda z: np.exp(-0.5 * z**2) / (0.1 * np.sqrt(2 * np.pi))
    np.testing.assert_allclose(got, [(g(0) + g(2)) / 2, (g(1) + g(1)) / 2],
                               rtol=1e-6)
    # A density: it integrates to one over a wide enough line.
    centres = jnp.linspace(-1, 2, 3001)
    dens = calibration.mass_distribution(x, centres, 0.1)
    self.assertAlmostEqual(float(jnp.sum(dens) * 1e-3), 1.0, places=4)

  def test_zero_at_the_truth_and_positive_elsewhere(self):
    values = self.problem(np.array([TRUTH, START, (35.0, 0.5)]))
    self.assertLess(values[0], 1e-10)
    self.assertGreater(values[1], 1e-2)
    self.assertGreater(values[2], 1e-3)
    self.assertEqual(self.problem.front_error(TRUTH), 0.0)
    self.assertGreater(self.problem.front_error(START), 0.05)

  def test_batched_equals_single_and_gradient_points_downhill(self):
    theta = np.array([33.0, 0.5])
    batched = self.problem(theta[None])[0]
    value, grad = self.problem.value_and_grad(theta)
    # A vmapped program is not the same float32 arithmetic as the single
    # one: 2.5e-5 apart on an AMD EPYC CPU, 1e-5 elsewhere.
    np.testing.assert_allclose(value, batched, rtol=1e-4)
    # Basal friction above the truth: the deposit stops short, and the
    # gradient says lower it.
    self.assertGreater(grad[1], 0)
    step = 0.01
    below = self.problem(np.array([[33.0, 0.5 - step]]))[0]
    self.assertLess(below, value)

  def test_cmaes_recovers_the_hidden_values(self):
    result = calibration.calibrate("cmaes", self.problem, START,
                                   budget=baselines.Budget(96))
    self.assertLen(result["trace"], 96)
    best = min(result["trace"], key=lambda r: r["value"])
    angle, basal = best["vector"]
    self.assertLess(abs(angle - TRUTH[0]), 1.0)
    self.assertLess(abs(basal - TRUTH[1]), 0.02)
    self.assertLess(self.problem.front_error(best["vector"]), 0.02)

  def test_adam_respects_its_budget_and_the_box(self):
    trace = calibration.adam(self.problem, (49.9, 0.11),
                             budget=baselines.Budget(3), learning_rate=0.3)
    self.assertLen(trace, 3)
    for r in trace:
      lo, hi = calibration.BOUNDS
      self.assertTrue(np.all(lo <= r["vector"]) and np.all(r["vector"] <= hi))

  def test_bad_values_are_refused(self):
    for theta, text in (((60.0, 0.4), "friction_angle_deg = 60"),
                        ((35.0, 1.5), "basal_friction = 1.5"),
                        ((35.0,), "two finite numbers")):
      with self.assertRaisesRegex(mpm.InputError, text):
        calibration.check(theta)
    with self.assertRaisesRegex(ValueError, "allowed"):
      calibration.calibrate("bfgs", self.problem, START,
                            budget=baselines.Budget(1))


if __name__ == "__main__":
  absltest.main()
