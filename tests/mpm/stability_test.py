"""Stability tests for `mpm.solver` and `mpm.simulation` at the edges of the
parameter ranges: stiff and soft sand, weak and strong friction, the largest
obstacles, walls, one particle and many."""

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mpm
from mpm import geometry
from mpm import sampler

FLOOR = 0.05
_SOLID_SDF = jax.jit(geometry.solid_sdf)
_OBSTACLE_SDF = jax.jit(geometry.obstacle_sdf)
_MATERIAL = {"density": 1500.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3,
             "friction_angle_deg": 35.0}


def _small(**kw):
  """Sand dropped 2 cm onto a flat floor in a 0.3 m box, 0.05 s."""
  d = {"name": "small", "domain": {"width": 0.3, "height": 0.3},
       "ramp": {"kind": "polynomial", "coefficients": [FLOOR]},
       "granular": {"box": [0.1, FLOOR + 0.02, 0.2, FLOOR + 0.08],
                    "spacing": 0.01},
       "material": _MATERIAL,
       "solver": {"dx": 0.02, "cfl": 0.4}, "num_frames": 6, "frame_dt": 0.01}
  d.update(kw)
  return mpm.Scene.from_dict(d)


class StabilityTest(parameterized.TestCase):

  def _check(self, scene, result, penetration_cells=0.5):
    """Finite, inside the domain, out of the solids (to half a cell)."""
    p = result.positions
    self.assertEqual(p.shape[0], scene.num_frames)
    self.assertTrue(np.all(np.isfinite(p)))
    self.assertTrue(np.all(p >= 0))
    self.assertTrue(np.all(p <= [scene.domain.width, scene.domain.height]))
    ramp = geometry.ramp_params(scene.ramp)
    obstacles = tuple(geometry.obstacle_params(o) for o in scene.obstacles)
    phi = _SOLID_SDF(ramp, obstacles, jnp.asarray(p))
    self.assertGreater(float(jnp.min(phi)), -penetration_cells * scene.dx)
    self.assertTrue(np.all(np.isfinite(result.max_speed)))

  def test_substeps_grow_with_stiffness(self):
    counts = []
    for e in (1e4, 1e5, 1e6, 1e7):
      scene = _small(material=dict(_MATERIAL, youngs_modulus=e))
      n = mpm.setup(scene).n_substeps
      # dt <= cfl dx / (c_p + v_max): the substep resolves the P wave.
      c_p = mpm.simulation.wave_speed(scene.material)
      self.assertLessEqual(scene.frame_dt / n * c_p,
                           scene.solver.cfl * scene.dx * (1 + 1e-6))
      counts.append(n)
    self.assertEqual(counts, sorted(counts))
    # c_p grows like sqrt(E): 1e3 in E is ~30x in substeps once c_p >> v.
    self.assertGreater(counts[-1], 10 * counts[0])

  @parameterized.parameters(1e4, 1e5, 1e6, 1e7)
  def test_youngs_modulus(self, e):
    scene = _small(material=dict(_MATERIAL, youngs_modulus=e))
    result = mpm.simulate(scene)
    self._check(scene, result)
    self.assertEqual(result.n_substeps, mpm.setup(scene).n_substeps)

  @parameterized.parameters(20.0, 35.0, 50.0)
  def test_friction_angles(self, phi):
    scene = _small(material=dict(_MATERIAL, friction_angle_deg=phi))
    self._check(scene, mpm.simulate(scene))

  def test_friction_angle_orders_runout(self):
    # Weaker sand spreads further: the heap of 20 degree sand is wider than
    # that of 50 degree sand after 0.15 s.
    widths = []
    for phi in (20.0, 50.0):
      scene = _small(material=dict(_MATERIAL, friction_angle_deg=phi),
                     num_frames=16)
      p = mpm.simulate(scene).positions
      widths.append(np.ptp(p[-1, :, 0]))
    self.assertGreater(widths[0], widths[1] + 0.01)

  @parameterized.parameters(("semicircle", "rectangle"),
                            ("rectangle", "triangle"),
                            ("triangle", "semicircle"))
  def test_largest_obstacles_on_paper_ramp(self, shape_a, shape_b):
    # Table 1's largest sizes at both ends of its range of x, on the paper's
    # ramp; a block of sand falls onto each from 1 cm.
    obstacles = [
        {"shape": shape, "x": x,
         **{k: hi for k, (lo, hi) in sampler.SIZE_RANGES[shape].items()}}
        for shape, x in ((shape_a, 0.5), (shape_b, 1.3))]
    scene = mpm.Scene.from_dict({
        "name": f"{shape_a}_{shape_b}", "obstacles": obstacles,
        "num_frames": 9, "frame_dt": 0.01})
    outline, types = mpm.boundary_particles(scene)
    outline = outline[types == mpm.OBSTACLE_TYPE]
    blocks = []
    for o in obstacles:
      # A layer 1 cm above the ramp and the obstacle, draped over both.
      for x in o["x"] + 0.005 * (np.arange(24) - 11.5):
        below = outline[np.abs(outline[:, 0] - x) < 0.006, 1]
        base = max([float(scene.ramp.height(x))] + below.tolist()) + 0.01
        blocks += [(x, base + 0.005 * (k + 0.5)) for k in range(4)]
    result = mpm.simulate_setups([mpm.setup(scene, np.array(blocks))])[0]
    self._check(scene, result)
    # The sand reached both obstacles: it rests within the boundary band
    # (the condition fades out over one cell outside a solid), plus half a
    # particle spacing.
    ramp = geometry.ramp_params(scene.ramp)
    for o in scene.obstacles:
      d = _OBSTACLE_SDF(ramp, geometry.obstacle_params(o),
                        jnp.asarray(result.positions[-1]))
      self.assertLess(float(jnp.min(d)), 1.5 * scene.dx, o.shape)

  @parameterized.named_parameters(("left", 0.0, 0.08), ("right", 0.22, 0.3))
  def test_sand_touching_a_wall(self, x0, x1):
    scene = _small(granular={"box": [x0, FLOOR + 0.02, x1, FLOOR + 0.1],
                             "spacing": 0.01}, wall_friction=0.3)
    result = mpm.simulate(scene)
    self._check(scene, result)
    # It starts against the wall and stays against it.
    wall = 0.0 if x0 == 0.0 else 0.3
    self.assertLess(np.min(np.abs(result.positions[-1, :, 0] - wall)), 0.01)

  def test_single_particle(self):
    scene = _small(granular={"box": [0.14, 0.1, 0.16, 0.12], "spacing": 0.01,
                             "num_particles": 1},
                   num_frames=41, frame_dt=0.01)
    result = mpm.simulate(scene)
    self.assertEqual(result.positions.shape, (41, 1, 2))
    self._check(scene, result)
    # It fell onto the floor and stopped there.
    self.assertLess(result.positions[-1, 0, 1], FLOOR + scene.dx)
    self.assertLess(result.max_speed[-1], 0.01)

  @pytest.mark.slow
  def test_5000_particles(self):
    scene = mpm.Scene.from_dict({
        "name": "many", "granular": {"box": [1.0, 0.6, 1.6, 1.1],
                                     "spacing": 0.005, "num_particles": 5000},
        "num_frames": 5})
    result = mpm.simulate(scene)
    self.assertEqual(result.positions.shape, (5, 5000, 2))
    self._check(scene, result)


if __name__ == "__main__":
  absltest.main()
