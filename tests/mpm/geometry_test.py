"""Tests for `mpm.geometry`: boundary particles, differentiable form."""

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from mpm import geometry

TRIANGLE_AND_SEMICIRCLE = {
    "name": "two", "obstacles": [
        {"shape": "triangle", "x": 0.7, "base": 0.05, "height": 0.04},
        {"shape": "semicircle", "x": 1.0, "radius": 0.03}],
    "granular": {"box": [1.25, 0.5, 1.46, 1.19], "spacing": 0.01}}


def reference_boundary_particles(scene):
  """The boundary particles as ``boundary_particles`` built them before it
  reused ``boundary_nodes``: each obstacle's SDF drops the ramp points it
  covers, each outline is sampled at ``linspace(0, 1, outline_size)``."""
  spacing = scene.granular.spacing
  ramp = geometry.ramp_params(scene.ramp)
  surface = geometry.ramp_surface(scene.ramp, scene.domain, spacing)
  sdf, outline = jax.jit(geometry.obstacle_sdf), jax.jit(
      geometry.obstacle_outline)
  obstacles = [geometry.obstacle_params(o) for o in scene.obstacles]
  if obstacles:
    phi = np.min([np.asarray(sdf(ramp, o, surface)) for o in obstacles], 0)
    surface = surface[phi >= 0]
  outlines = [np.asarray(outline(ramp, p, jnp.asarray(np.linspace(
      0.0, 1.0, geometry.outline_size(o, spacing)), jnp.float32)))
              for p, o in zip(obstacles, scene.obstacles)]
  types = np.concatenate([np.full(len(surface), mpm.RAMP_TYPE)] + [
      np.full(len(p), mpm.OBSTACLE_TYPE) for p in outlines])
  return np.concatenate([surface] + outlines).astype(np.float32), types


class BoundaryParticlesTest(parameterized.TestCase):

  @parameterized.parameters(0, 4, 5, 9)  # none, two rectangles, mixed
  def test_sampled_scenes_match_the_reference(self, seed):
    self._check(mpm.sample_scene(seed))

  def test_triangle_and_semicircle_match_the_reference(self):
    self._check(mpm.Scene.from_dict(TRIANGLE_AND_SEMICIRCLE))

  def _check(self, scene):
    want, want_types = reference_boundary_particles(scene)
    got, types = mpm.boundary_particles(scene)
    np.testing.assert_array_equal(types, want_types)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)


class BoundaryNodesTest(parameterized.TestCase):

  def _nodes(self, scene, parking=None):
    spacing = scene.granular.spacing
    surface = geometry.ramp_surface(scene.ramp, scene.domain, spacing)
    fractions = [geometry.outline_fractions(geometry.outline_size(o, spacing))
                 for o in scene.obstacles]
    obstacles = tuple(geometry.obstacle_params(o) for o in scene.obstacles)
    return surface, jax.jit(geometry.boundary_nodes)(
        geometry.ramp_params(scene.ramp), obstacles, surface, fractions,
        parking)

  def test_parked_ramp_points_keep_the_node_count(self):
    scene = mpm.Scene.from_dict(TRIANGLE_AND_SEMICIRCLE)
    surface, plain = self._nodes(scene)
    parking = np.full_like(surface, -1.0)
    _, parked = self._nodes(scene, parking)
    covered = np.asarray(plain.covered)
    self.assertTrue(covered.any())
    self.assertEqual(parked.ramp.shape, surface.shape)
    np.testing.assert_array_equal(np.asarray(parked.ramp)[covered], -1.0)
    np.testing.assert_allclose(np.asarray(parked.ramp)[~covered],
                               surface[~covered], atol=1e-6)
    # Dropping the covered points gives the scene's boundary particles.
    want, _ = mpm.boundary_particles(scene)
    got = np.concatenate([surface[~covered]] +
                         [np.asarray(o) for o in plain.outlines])
    np.testing.assert_allclose(got, want, atol=1e-6)

  @parameterized.parameters(
      ("semicircle", 1.0, [0.03, 0.0]), ("rectangle", 0.9, [0.05, 0.04]),
      ("triangle", 0.8, [0.05, 0.04]))
  def test_gradient_matches_central_differences(self, shape, x, size):
    # float64: differences of h = 1e-6 m resolve the derivative to ~1e-8.
    with jax.enable_x64(True):
      scene = mpm.Scene.from_dict({"name": "g"})
      ramp = jax.tree.map(lambda a: a.astype(jnp.float64),
                          geometry.ramp_params(scene.ramp))
      surface = geometry.ramp_surface(scene.ramp, scene.domain, 0.01)
      s = np.linspace(0.0, 1.0, 17)
      weights = np.random.default_rng(0).normal(size=(len(surface) + 17, 2))

      def loss(x, size):
        o = geometry.ObstacleParams(x, size, shape)
        nodes = geometry.boundary_nodes(ramp, (o,), surface, (s,),
                                        np.full_like(surface, -1.0))
        return jnp.sum(weights * jnp.concatenate([nodes.ramp,
                                                  *nodes.outlines]))

      x, size, h = jnp.float64(x), jnp.asarray(size, jnp.float64), 1e-6
      grad_x, grad_size = jax.jit(jax.grad(loss, argnums=(0, 1)))(x, size)
      f = jax.jit(loss)
      fd_x = (f(x + h, size) - f(x - h, size)) / (2 * h)
      fd_size = [(f(x, size + e) - f(x, size - e)) / (2 * h)
                 for e in h * np.eye(2)]
    self.assertGreater(abs(float(grad_x)), 1e-3)  # the outline moves with x
    np.testing.assert_allclose(float(grad_x), float(fd_x), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(grad_size), np.asarray(fd_size),
                               rtol=1e-5, atol=1e-8)


class SDFGridTest(absltest.TestCase):

  def test_points_far_outside_the_domain_are_pushed_back_in(self):
    scene = mpm.Scene.from_dict({})
    grid = mpm.scene_sdf_grid(scene, 0.01)
    rng = np.random.default_rng(0)
    w, h = scene.domain.width, scene.domain.height
    p = rng.uniform([-1.0, -1.0], [w + 1.0, h + 1.0], (500, 2))
    p = p[geometry.domain_sdf(w, h, p) < -0.02].astype(np.float32)
    phi, normal = mpm.sample_sdf(grid, jnp.asarray(p))
    # Outside the box, the distance is at least the distance to the box.
    np.testing.assert_array_less(np.asarray(phi),
                                 np.asarray(geometry.domain_sdf(w, h, p))
                                 + 1e-5)
    inside = np.asarray(mpm.push_out(jnp.asarray(p), phi, normal))
    self.assertTrue(np.all(geometry.domain_sdf(w, h, inside) > -1e-5))


if __name__ == "__main__":
  absltest.main()
