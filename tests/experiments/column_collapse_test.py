"""Tests for `experiments.column_collapse`: the extrapolation, the runout and
the column scene (no long simulation)."""

from absl.testing import absltest
import numpy as np

import mpm
from experiments import column_collapse


class ConvergenceTest(absltest.TestCase):

  def test_richardson_recovers_a_first_and_a_second_order_limit(self):
    for order in (1, 2):
      h = np.array([0.4, 0.2, 0.1])
      value, got = column_collapse.richardson(list(1.5 - 0.7 * h**order))
      self.assertAlmostEqual(value, 1.5, places=12)
      self.assertAlmostEqual(got, order, places=12)

  def test_richardson_refuses_changes_that_do_not_shrink(self):
    for values in ([0.6, 0.8, 1.1], [0.6, 0.8, 0.7], [0.6, 0.6, 0.6]):
      value, order = column_collapse.richardson(values)
      self.assertTrue(np.isnan(value) and np.isnan(order), values)

  def test_runouts_of_a_final_deposit(self):
    x = np.linspace(0.0, 0.3, 1001)    # a deposit reaching 0.3 m
    front, q995 = column_collapse.runouts(x, width0=0.1)
    self.assertAlmostEqual(front, 2.0)
    self.assertAlmostEqual(q995, (np.quantile(x, 0.995) - 0.1) / 0.1)

  def test_column_scene(self):
    scene = column_collapse.column_scene(2.0, 0.005, height=0.1)
    np.testing.assert_allclose(scene.granular.box, (0.0, 0.02, 0.05, 0.12))
    self.assertAlmostEqual(scene.dx, 0.01)
    self.assertEqual(scene.wall_friction, 0.0)
    self.assertAlmostEqual(scene.boundary_friction, 0.7)
    # The column is filled: (0.05 / 0.005) x (0.1 / 0.005) particles.
    self.assertLen(mpm.granular_particles(scene), 10 * 20)


if __name__ == "__main__":
  absltest.main()
