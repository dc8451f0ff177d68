"""Tests for `gnsjax.design.placement`."""

from absl.testing import absltest
import jax.numpy as jnp
import numpy as np

from gnsjax.design import placement as placement_lib
from mpm import scene as scene_lib
from tests.gnsjax.design.fixtures import scene

Placement = placement_lib.Placement
# A ValueError the entry points print in one line.
InputError = scene_lib.InputError


class PlacementTest(absltest.TestCase):

  def test_projection_keeps_parameters_in_range(self):
    p = Placement(scene(), free=("x", "size"))
    out = p.project({"x": jnp.float32(2.0), "size": jnp.asarray([0.5, 0.0])})
    self.assertAlmostEqual(float(out["x"]), 1.3, places=6)
    np.testing.assert_allclose(out["size"], [0.05, 0.0])
    out = p.project({"x": jnp.float32(-1.0), "size": jnp.asarray([0.0, 0.0])})
    self.assertAlmostEqual(float(out["x"]), 0.5, places=6)
    np.testing.assert_allclose(out["size"], [0.02, 0.0])
    p.check(out)  # a projected placement is valid

  def test_x_outside_the_range_is_refused(self):
    p = Placement(scene())
    with self.assertRaisesRegex(InputError, r"x = 1.4.*\[0.5, 1.3\]"):
      p.check({"x": jnp.float32(1.4)})
    with self.assertRaisesRegex(InputError, r"x = 0.45.*\[0.5, 1.3\]"):
      Placement(scene(obstacles=[{"shape": "semicircle", "x": 0.45,
                                  "radius": 0.03}]))

  def test_obstacle_off_the_ramp_or_missing_is_refused(self):
    with self.assertRaisesRegex(InputError, "obstacle"):
      placement_lib.with_obstacle(scene(obstacles=[]), "semicircle", 1.8,
                                  radius=0.03)
    with self.assertRaisesRegex(InputError, "index = 0.*add the obstacle"):
      Placement(scene(obstacles=[]))
    with self.assertRaisesRegex(InputError, "free"):
      Placement(scene(), free=("size",))

  def test_scene_at_moves_the_obstacle(self):
    p = Placement(scene(), free=("x", "size"))
    s = p.scene_at({"x": jnp.float32(0.8), "size": jnp.asarray([0.04, 0.0])})
    self.assertAlmostEqual(s.obstacles[0].x, 0.8, places=6)
    self.assertAlmostEqual(s.obstacles[0].radius, 0.04, places=6)

  def test_fixed_scene_keeps_the_other_obstacles(self):
    two = placement_lib.with_obstacle(scene(), "rectangle", 0.8, width=0.04,
                                      height=0.03)
    p = Placement(two, index=1)
    self.assertEqual(p.fixed_scene().obstacles, two.obstacles[:1])


if __name__ == "__main__":
  absltest.main()
