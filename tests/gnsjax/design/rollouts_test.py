"""Tests for `gnsjax.design.rollouts`: gradients through both simulators."""

from unittest import mock

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mpm
from gnsjax import graph
from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from mpm import geometry
from tests.gnsjax.design.fixtures import C
from tests.gnsjax.design.fixtures import X
from tests.gnsjax.design.fixtures import TWO_OBSTACLES
from tests.gnsjax.design.fixtures import scene
from tests.gnsjax.design.fixtures import tiny_gns

Placement = placement_lib.Placement


class GradientTest(parameterized.TestCase):
  """jax.grad of the objectives through both simulators against central
  differences, on short rollouts where the sand meets the obstacle."""

  def _check(self, sim, objective, x, h, rtol):
    params = {"x": jnp.float32(x)}
    value, grad, positions = sim.value_and_grad(objective, params)
    fd = optimize.central_difference(
        lambda p: float(objective(jnp.asarray(sim.rollout(p)))), params, h)
    self.assertAlmostEqual(value, float(objective(jnp.asarray(positions))),
                           places=5)
    self.assertGreater(abs(float(grad["x"])), 1e-4)  # the obstacle matters
    np.testing.assert_allclose(float(grad["x"]), fd["x"], rtol=rtol)

  def _check_mpm(self, name):
    # Differences converge to the derivative as h shrinks (measured: 5%
    # off at h = 1e-3 m, 0.4% at 3e-4 m; contact makes the objective curve).
    p = Placement(scene(num_frames=40))
    obj = objectives.make(name, target_x=1.0)
    self._check(rollouts.MPMDriver(rollouts.MPMRollout.create(p)),
                obj.smooth, X, 3e-4, 0.05)

  def test_mpm_gradient_matches_central_differences(self):
    self._check_mpm("centroid")

  @pytest.mark.slow  # the runout's gradient: the four-parameter test's
  def test_mpm_gradient_of_the_runout_matches_central_differences(self):
    self._check_mpm("runout")

  def test_mpm_gradient_in_four_parameters_matches_central_differences(self):
    # Two obstacles, x and radius each, on 40 frames: every entry matters
    # and agrees with differences at h = 3e-4 m. The downstream obstacle's
    # entries are 100x smaller (the sand only reaches its edge), where
    # float32 differences carry ~1e-4 of noise.
    p = placement_lib.MultiPlacement(scene(obstacles=TWO_OBSTACLES,
                                           num_frames=40))
    sim = rollouts.MPMDriver(rollouts.MPMRollout.create(p))
    obj = objectives.make("runout").smooth
    params = p.initial()
    _, grad, _ = sim.value_and_grad(obj, params)
    fd = optimize.central_difference(
        lambda q: float(obj(jnp.asarray(sim.rollout(q)))), params, 3e-4)
    got = p.to_vector(grad)
    want = p.to_vector({k: jnp.asarray(v) for k, v in fd.items()})
    self.assertTrue(np.all(np.abs(got) > 1e-4), got)
    np.testing.assert_allclose(got, want, rtol=0.1, atol=2e-4)

  @parameterized.named_parameters(("boundary_particles", True, 20),
                                  ("sdf_only", False, 10))
  def test_gns_gradient_matches_central_differences(self, boundary, frames):
    # The radius graph makes the rollout jump where an edge appears (with a
    # message of full size), so differences across a few mm see jumps that
    # the derivative does not. With the graph held at its first step's edges
    # the rollout is smooth but for small jumps of what the model sees of the
    # solids: a node of the SDF grid between the ramp and the obstacle
    # changes its normal from one to the other as the obstacle moves, and
    # the constraint removes a particle's inward velocity only once it is
    # inside. Measured: differences of 1 mm are 2-4x off, of 0.3 mm within
    # 2%. Between those, the derivative through the model, the integration,
    # the remat'd scan, the solid constraint and what the model sees of the
    # obstacle (its SDF grid, and its boundary particles if they are nodes)
    # must match.
    p = Placement(scene(num_frames=frames))
    driver = tiny_gns(p, frames, boundary=boundary)
    self.assertLen(driver.sim.types,
                   driver.sim.n_sand + (len(gns_boundary(driver)) if boundary
                                        else 0))
    obj = objectives.make("runout")
    loss = lambda q, sim, mp, nb: obj.smooth(rollouts.gns_positions(
        sim, q, mp, nb, update_graph=False)[0])
    args = (driver.sim, driver.model_params, driver.nbrs)
    params = {"x": jnp.float32(X)}
    grad = jax.jit(jax.grad(loss))(params, *args)
    fd = optimize.central_difference(
        lambda q: float(jax.jit(loss)(q, *args)), params, 3e-4)
    self.assertGreater(abs(float(grad["x"])), 1e-2)
    np.testing.assert_allclose(float(grad["x"]), fd["x"], rtol=0.05)


def gns_boundary(driver):
  return rollouts.gns_boundary(driver.sim, driver.placement.initial())


class GNSRolloutTest(absltest.TestCase):

  def test_boundary_follows_the_obstacle(self):
    p = Placement(scene(num_frames=10))
    sim = tiny_gns(p, 10).sim
    nodes = np.asarray(rollouts.gns_boundary(sim, {"x": jnp.float32(1.0)}))
    # The designed obstacle's outline matches the scene's own particles.
    want, types = mpm.boundary_particles(p.scene_at({"x": jnp.float32(1.0)}))
    outline = want[types == mpm.OBSTACLE_TYPE]
    np.testing.assert_allclose(nodes[-len(outline):], outline, atol=1e-6)
    # Ramp particles under it are parked below the domain, the rest kept.
    ramp = nodes[:len(sim.ramp_points)]
    kept = ramp[ramp[:, 1] >= 0]
    np.testing.assert_allclose(kept, want[types == mpm.RAMP_TYPE], atol=1e-6)

  def test_neighbour_list_grows_instead_of_truncating(self):
    p = Placement(scene(num_frames=12))
    driver = tiny_gns(p, 12)
    ample = driver.rollout(p.initial())
    # A list sized for isolated nodes (self-edges only) overflows at once:
    # the rollout must reallocate and agree.
    n, spec = len(driver.sim.types), driver.sim.spec
    driver.nbrs = graph.allocate(spec, graph.parking_positions(n, spec))
    small = driver.nbrs.idx.shape[-1]
    np.testing.assert_allclose(driver.rollout(p.initial()), ample, atol=1e-6)
    self.assertGreater(driver.nbrs.idx.shape[-1], small)

  def test_settings_are_part_of_the_compiled_program(self):
    # The number of frames is static: a rollout with another is another
    # object and another program, never a stale one (a closure over a
    # mutable object kept its first length).
    p = Placement(scene(num_frames=12))
    sand = mpm.granular_particles(p.scene)
    driver = tiny_gns(p, 12, window=np.repeat(sand[None], C, 0))
    self.assertLen(driver.rollout(p.initial()), 12)
    longer = rollouts.GNSDriver(driver.sim.replace(num_frames=15),
                                driver.model_params, driver.nbrs)
    self.assertLen(longer.rollout(p.initial()), 15)
    self.assertLen(driver.rollout(p.initial()), 12)
    with self.assertRaisesRegex(ValueError, "must exceed the 6 input"):
      tiny_gns(p, C, window=np.repeat(sand[None], C, 0))

  def test_frame_stride_and_sdf_only_nodes(self):
    p = Placement(scene(num_frames=20))
    sand = mpm.granular_particles(p.scene)
    window = np.repeat(sand[None], C, 0)
    # Stride 2 from frames 0, 2, ..., 10: learned steps to 12, ..., 18.
    driver = tiny_gns(p, 20, window=window, frame_stride=2, boundary=False)
    self.assertEqual(driver.sim.n_steps, 4)
    self.assertLen(driver.sim.types, len(sand))
    self.assertEqual(gns_boundary(driver).shape, (0, 2))
    positions = driver.rollout(p.initial())
    self.assertEqual(positions.shape, (C + 4, len(sand), 2))
    np.testing.assert_array_equal(positions[:C], window)
    # The SDF grid follows the obstacle.
    moved = {"x": jnp.float32(1.0)}
    np.testing.assert_allclose(
        rollouts.gns_solids(driver.sim, moved).values,
        geometry.scene_sdf_grid(p.scene_at(moved), 0.005).values, atol=1e-5)
    with self.assertRaisesRegex(ValueError, "must exceed the 6 input frames "
                                "at stride 2"):
      tiny_gns(p, 11, window=window, frame_stride=2)

  def test_mpm_window_at_a_stride(self):
    s = scene(num_frames=20)
    every = rollouts.mpm_window(s, 5)           # frames 0..4
    strided = rollouts.mpm_window(s, 3, 2)      # frames 0, 2, 4
    self.assertEqual(strided.dtype, np.float32)
    np.testing.assert_array_equal(strided, every[::2])

  def test_constructors_run_no_simulation(self):
    p = Placement(scene(num_frames=12))
    sand = mpm.granular_particles(p.scene)
    refuse = mock.Mock(side_effect=AssertionError("simulated"))
    with mock.patch.object(mpm, "simulate", refuse), \
        mock.patch.object(mpm.simulation, "simulate_setups", refuse):
      tiny_gns(p, 12, window=np.repeat(sand[None], C, 0))
      rollouts.MPMRollout.create(p)
    refuse.assert_not_called()


class NonFiniteGradientTest(absltest.TestCase):

  def test_error_names_the_scene_and_the_frame(self):
    p = Placement(scene(num_frames=6))
    sim = rollouts.MPMDriver(rollouts.MPMRollout.create(p))
    params = p.initial()
    y = sim.rollout(params)[:, :, 1]                     # [T, N] (m)
    # A falling particle that crosses a height between frames 2 and 3:
    # sqrt(max(y - h, 0)) has an infinite derivative there (NaN after max).
    frame = 3
    i = int(np.argmax(y[frame - 1] - y[frame]))
    h = float(y[frame - 1, i] + y[frame, i]) / 2
    self.assertTrue(np.all(y[:frame, i] > h) and y[frame, i] < h)

    def broken(x):
      return jnp.mean(x[-1, :, 0]) + jnp.sum(
          jnp.sqrt(jnp.maximum(x[:, i, 1] - h, 0.0)))

    with self.assertRaisesRegex(
        FloatingPointError, r"scene design_test: the gradient of broken "
        rf"w.r.t. x is not finite from frame {frame}\b"):
      sim.value_and_grad(broken, params)

  def test_gns_error_names_the_scene_and_the_frame(self):
    p = Placement(scene())
    driver = tiny_gns(p, num_frames=C + 2)   # two learned steps
    params = p.initial()
    # The untrained model moves the sand at random: take the coordinate
    # (particle i, axis a, sign s) that first leaves its range at the
    # second learned step, and put h between.
    frame = C + 1
    x = driver.rollout(params)                           # [T, Ns, 2] (m)
    u = np.stack([x, -x])                                # [2, T, Ns, 2]
    margin = np.min(u[:, :frame], 1) - u[:, frame]       # [2, Ns, 2]
    sign, i, a = np.unravel_index(np.argmax(margin), margin.shape)
    s = 1.0 - 2.0 * sign
    h = float(np.min(u[sign, :frame, i, a]) + u[sign, frame, i, a]) / 2
    self.assertTrue(np.all(u[sign, :frame, i, a] > h) and
                    u[sign, frame, i, a] < h)

    def broken(x):
      return jnp.mean(x[-1, :, 0]) + jnp.sum(
          jnp.sqrt(jnp.maximum(s * x[:, i, a] - h, 0.0)))

    with self.assertRaisesRegex(
        FloatingPointError, r"scene design_test: the gradient of broken "
        rf"w.r.t. x is not finite from frame {frame}\b"):
      driver.value_and_grad(broken, params)


if __name__ == "__main__":
  absltest.main()
