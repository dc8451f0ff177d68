"""Tests for `gnsjax.design.placement`."""

from absl.testing import absltest
import jax.numpy as jnp
import numpy as np

from gnsjax.design import placement as placement_lib
from mpm import scene as scene_lib
from tests.gnsjax.design.fixtures import TWO_OBSTACLES
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


class MultiPlacementTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    self.p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES))

  def test_vector_round_trip_and_bounds(self):
    self.assertEqual(self.p.names, ("x0", "radius0", "x1", "radius1"))
    lo, hi = self.p.bounds()
    np.testing.assert_allclose(lo, [0.5, 0.02, 0.5, 0.02])
    np.testing.assert_allclose(hi, [1.3, 0.05, 1.3, 0.05])
    v = np.array([0.7, 0.03, 1.0, 0.045])
    params = self.p.from_vector(v)
    np.testing.assert_allclose(params["size"], [[0.03, 0.0], [0.045, 0.0]])
    np.testing.assert_allclose(self.p.to_vector(params), v, rtol=1e-6)

  def test_projection_keeps_every_parameter_in_range_and_apart(self):
    rng = np.random.default_rng(0)
    lo, hi = self.p.bounds()
    for _ in range(200):
      # Anywhere, also far outside the box and on top of each other.
      v = rng.uniform(lo - 0.3, hi + 0.3)
      if rng.random() < 0.3:
        v[2] = v[0] + rng.uniform(-0.01, 0.01)
      q = self.p.project(self.p.from_vector(v))
      w = self.p.to_vector(q)
      self.assertTrue(np.all(w >= lo - 1e-6) and np.all(w <= hi + 1e-6), w)
      self.assertGreaterEqual(abs(w[2] - w[0]), w[1] + w[3] - 1e-6)
      self.p.check(q)  # a projected placement is valid
      # A valid placement is its own projection.
      np.testing.assert_allclose(self.p.to_vector(self.p.project(q)), w,
                                 atol=1e-6)

  def test_projection_separates_symmetrically(self):
    q = self.p.project({"x": jnp.array([1.0, 1.02]),
                        "size": jnp.array([[0.03, 0.0], [0.03, 0.0]])})
    # 0.04 short of 0.06 apart: each moves 0.02 away from the other.
    np.testing.assert_allclose(q["x"], [0.98, 1.04], atol=1e-4)

  def test_overlapping_or_out_of_range_obstacles_are_refused(self):
    with self.assertRaisesRegex(InputError, "overlaps.*at least 0.060 m"):
      self.p.check({"x": jnp.array([1.0, 1.03]),
                    "size": jnp.array([[0.03, 0.0], [0.03, 0.0]])})
    with self.assertRaisesRegex(InputError,
                                r"obstacle 1: .*x = 1.4.*\[0.5, 1.3\]"):
      self.p.check({"x": jnp.array([1.0, 1.4]),
                    "size": jnp.array([[0.03, 0.0], [0.03, 0.0]])})
    with self.assertRaisesRegex(InputError, "obstacle 0: .*size"):
      self.p.check({"x": jnp.array([1.0, 1.2]),
                    "size": jnp.array([[0.08, 0.0], [0.03, 0.0]])})
    with self.assertRaisesRegex(InputError, "indices.*distinct"):
      placement_lib.MultiPlacement(scene(), indices=(0, 1))

  def test_scene_at_moves_both_and_obstacles_follow_params(self):
    params = {"x": jnp.array([0.7, 1.1]),
              "size": jnp.array([[0.04, 0.0], [0.025, 0.0]])}
    s = self.p.scene_at(params)
    self.assertAlmostEqual(s.obstacles[0].x, 0.7, places=6)
    self.assertAlmostEqual(s.obstacles[1].radius, 0.025, places=6)
    o = self.p.obstacles(params)
    np.testing.assert_allclose([o[0].x, o[1].x], [0.7, 1.1])


if __name__ == "__main__":
  absltest.main()
