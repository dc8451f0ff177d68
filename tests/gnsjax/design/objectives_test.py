"""Tests for `gnsjax.design.objectives`."""

from absl.testing import absltest
import jax.numpy as jnp
import numpy as np

from gnsjax.design import objectives


class ObjectivesTest(absltest.TestCase):

  def test_soft_min_bounds_the_minimum(self):
    v = jnp.asarray([0.3, 0.5, 0.31, 0.9])
    tau = 0.01
    m = float(objectives.soft_min(v, tau))
    self.assertLessEqual(m, 0.3)
    self.assertGreaterEqual(m, 0.3 - tau * np.log(len(v)))

  def test_smooth_values_approach_the_plain_ones(self):
    rng = np.random.default_rng(0)
    positions = rng.uniform(0.2, 1.4, (3, 500, 2)).astype(np.float32)
    for name in objectives.NAMES:
      cold = objectives.make(name, x_protect=0.7, target_x=0.5,
                             temperature=1e-4)
      self.assertAlmostEqual(float(cold.smooth(jnp.asarray(positions))),
                             cold.plain(positions), delta=0.02, msg=name)

  def test_passed_fraction_counts_by_hand(self):
    final = np.array([[0.1, 0], [0.5, 0], [0.55, 0], [0.9, 0]], np.float32)
    positions = np.stack([final + 1.0, final])
    obj = objectives.make("passed_fraction", x_protect=0.52)
    self.assertEqual(obj.plain(positions), 0.5)
    centroid = objectives.make("centroid", target_x=0.5)
    self.assertAlmostEqual(centroid.plain(positions), (0.5125 - 0.5)**2,
                           places=7)

  def test_unknown_objective_and_bad_temperature(self):
    with self.assertRaisesRegex(ValueError, "allowed.*runout"):
      objectives.make("height")
    with self.assertRaisesRegex(ValueError, "temperature"):
      objectives.make("runout", temperature=0.0)


if __name__ == "__main__":
  absltest.main()
