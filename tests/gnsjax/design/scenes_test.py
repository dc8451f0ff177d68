"""Tests for `gnsjax.design.scenes`: the problems' scenes, in range."""

from absl.testing import absltest
import numpy as np

import mpm
from gnsjax.design import placement as placement_lib
from gnsjax.design import scenes


class ScenesTest(absltest.TestCase):

  def test_one_and_two_obstacles_on_the_heap(self):
    scene = scenes.one_obstacle("rectangle", (0.03, 0.02), 0.9, 12)
    self.assertEqual(scene.name, "design_rectangle")
    self.assertEqual(scene.num_frames, 12)
    self.assertEqual((scene.granular.spacing, scene.granular.num_particles),
                     (0.01, 250))
    (o,) = scene.obstacles
    self.assertEqual((o.shape, o.x, o.width, o.height),
                     ("rectangle", 0.9, 0.03, 0.02))
    with self.assertRaisesRegex(ValueError, r"a semicircle needs 1 value\(s\)"):
      scenes.one_obstacle("semicircle", (0.03, 0.04))
    two = scenes.two_obstacles((0.9, 1.1), (0.03, 0.04), num_frames=2)
    self.assertEqual([(o.x, o.radius) for o in two.obstacles],
                     [(0.9, 0.03), (1.1, 0.04)])
    self.assertEqual(scenes.heap("calibrate").obstacles, ())
    with self.assertRaises(mpm.InputError):     # overlapping
      scenes.two_obstacles((1.0, 1.02), num_frames=2)

  def test_a_row_of_baffles_in_range_and_kept_apart(self):
    scene = scenes.baffles(6, num_frames=2)
    shapes = {(o.shape, o.width, o.height) for o in scene.obstacles}
    self.assertEqual(shapes, {("rectangle",) + scenes.BAFFLE_SIZE})
    p = placement_lib.MultiPlacement(scene, indices=tuple(range(6)),
                                     free=("x",))
    x = p.to_vector(p.initial())
    lo, hi = placement_lib.X_RANGE
    reach = scene.obstacles[0].reach
    self.assertLen(x, 6)
    np.testing.assert_allclose([x[0] - reach, x[-1] + reach], [lo, hi])
    # Three baffles asked at one place are pushed apart, inside the range.
    x[1:4] = 0.9
    repaired = p.to_vector(p.project(p.from_vector(x)))
    gaps = np.diff(np.sort(repaired))
    self.assertTrue(np.all(gaps >= 2 * reach - 1e-6), gaps)
    self.assertTrue(np.all((repaired >= lo) & (repaired <= hi)))
    p.check(p.from_vector(repaired))


if __name__ == "__main__":
  absltest.main()
