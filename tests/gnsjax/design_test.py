"""Tests for `gnsjax.design` and `gnsjax.objectives` (inverse design)."""


from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from gnsjax import design
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import objectives
from gnsjax import train

C = 6
# A small heap (spacing 0.01 m, 60 particles) released onto a semicircle:
# the obstacle acts on the sand from the first frames.
X = 1.28
SCENE = {
    "name": "design_test",
    "obstacles": [{"shape": "semicircle", "x": X, "radius": 0.03}],
    "granular": {"box": [1.25, 0.5, 1.46, 1.19], "spacing": 0.01,
                 "num_particles": 60},
}


def scene(**overrides) -> mpm.Scene:
  return mpm.Scene.from_dict({**SCENE, **overrides})


def tiny_gns(placement: design.Placement, num_frames: int):
  """A GNSRollout of an untrained two-step model (random weights)."""
  model = models.EncodeProcessDecode(latent_size=16, hidden_layers=1,
                                     num_message_passing_steps=2,
                                     type_embedding_size=4)
  params = model.init(jax.random.key(0), jnp.zeros((4, 2 * (C - 1) + 4)),
                      jnp.full(4, mpm.SAND_TYPE), jnp.zeros((4, 3)),
                      jnp.zeros(4, jnp.int32), jnp.zeros(4, jnp.int32))
  bounds = ((0.0, 1.65), (0.0, 1.19))
  stats = features.Stats(np.zeros(2, np.float32), np.full(2, 1e-3, np.float32),
                         np.zeros(2, np.float32), np.full(2, 1e-3, np.float32))
  problem = train.Problem(stats, np.asarray(bounds, np.float32), 0.03,
                          graph.GraphSpec(0.03, bounds))
  return design.GNSRollout(placement, model, params, problem, C, num_frames)


class ObjectivesTest(parameterized.TestCase):

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


class PlacementTest(parameterized.TestCase):

  def test_projection_keeps_parameters_in_range(self):
    p = design.Placement(scene(), free=("x", "size"))
    out = p.project({"x": jnp.float32(2.0), "size": jnp.asarray([0.5, 0.0])})
    self.assertAlmostEqual(float(out["x"]), 1.3, places=6)
    np.testing.assert_allclose(out["size"], [0.05, 0.0])
    out = p.project({"x": jnp.float32(-1.0), "size": jnp.asarray([0.0, 0.0])})
    self.assertAlmostEqual(float(out["x"]), 0.5, places=6)
    np.testing.assert_allclose(out["size"], [0.02, 0.0])
    p.check(out)  # a projected placement is valid

  def test_x_outside_the_range_is_refused(self):
    p = design.Placement(scene())
    with self.assertRaisesRegex(ValueError, r"x = 1.4.*\[0.5, 1.3\]"):
      p.check({"x": jnp.float32(1.4)})
    with self.assertRaisesRegex(ValueError, r"x = 0.45.*\[0.5, 1.3\]"):
      design.Placement(scene(obstacles=[{"shape": "semicircle", "x": 0.45,
                                         "radius": 0.03}]))

  def test_obstacle_off_the_ramp_or_missing_is_refused(self):
    with self.assertRaisesRegex(ValueError, "obstacle"):
      design.with_obstacle(scene(obstacles=[]), "semicircle", 1.8,
                           radius=0.03)
    with self.assertRaisesRegex(ValueError, "index = 0.*add the obstacle"):
      design.Placement(scene(obstacles=[]))
    with self.assertRaisesRegex(ValueError, "free"):
      design.Placement(scene(), free=("size",))

  def test_scene_at_moves_the_obstacle(self):
    p = design.Placement(scene(), free=("x", "size"))
    s = p.scene_at({"x": jnp.float32(0.8), "size": jnp.asarray([0.04, 0.0])})
    self.assertAlmostEqual(s.obstacles[0].x, 0.8, places=6)
    self.assertAlmostEqual(s.obstacles[0].radius, 0.04, places=6)


class GradientTest(parameterized.TestCase):
  """jax.grad of the objectives through both simulators against central
  differences, on short rollouts where the sand meets the obstacle."""

  def _check(self, sim, objective, x, h, rtol):
    params = {"x": jnp.float32(x)}
    value, grad, positions = sim.value_and_grad(objective, params)
    fd = design.central_difference(
        lambda p: float(objective(jnp.asarray(sim.rollout(p)))), params, h)
    self.assertAlmostEqual(value, float(objective(jnp.asarray(positions))),
                           places=5)
    self.assertGreater(abs(float(grad["x"])), 1e-4)  # the obstacle matters
    np.testing.assert_allclose(float(grad["x"]), fd["x"], rtol=rtol)

  @parameterized.parameters("centroid", "runout")
  def test_mpm_gradient_matches_central_differences(self, name):
    # Differences converge to the derivative as h shrinks (measured: 5%
    # off at h = 1e-3 m, 0.4% at 3e-4 m; contact makes the objective curve).
    p = design.Placement(scene(num_frames=40))
    obj = objectives.make(name, target_x=1.0)
    self._check(design.MPMRollout(p), obj.smooth, X, 3e-4, 0.05)

  def test_gns_gradient_matches_central_differences(self):
    # The radius graph makes the rollout jump where an edge appears (with a
    # message of full size), so differences across a few mm see jumps that
    # the derivative does not. With the graph held at its first step's edges
    # the rollout is smooth, and the derivative through the model, the
    # integration, the remat'd scan and the obstacle's boundary particles
    # must match.
    p = design.Placement(scene(num_frames=20))
    sim = tiny_gns(p, 20)
    obj = objectives.make("runout")
    loss = lambda q: obj.smooth(sim.positions(
        q, sim.model_params, sim.nbrs, update_graph=False)[0])
    params = {"x": jnp.float32(X)}
    grad = jax.jit(jax.grad(loss))(params)
    fd = design.central_difference(lambda q: float(jax.jit(loss)(q)), params,
                                   1e-3)
    self.assertGreater(abs(float(grad["x"])), 1e-4)
    np.testing.assert_allclose(float(grad["x"]), fd["x"], rtol=0.05)

  def test_gns_boundary_follows_the_obstacle(self):
    p = design.Placement(scene(num_frames=10))
    sim = tiny_gns(p, 10)
    nodes = np.asarray(sim.boundary({"x": jnp.float32(1.0)}))
    # The designed obstacle's outline matches the scene's own particles.
    want, types = mpm.boundary_particles(p.scene_at({"x": jnp.float32(1.0)}))
    outline = want[types == mpm.OBSTACLE_TYPE]
    np.testing.assert_allclose(nodes[-len(outline):], outline, atol=1e-6)
    # Ramp particles under it are parked below the domain, the rest kept.
    ramp = nodes[:len(sim.ramp_points)]
    kept = ramp[ramp[:, 1] >= 0]
    np.testing.assert_allclose(kept, want[types == mpm.RAMP_TYPE], atol=1e-6)

  def test_gns_neighbour_list_grows_instead_of_truncating(self):
    p = design.Placement(scene(num_frames=12))
    sim = tiny_gns(p, 12)
    ample = sim.rollout(p.initial())
    # A list sized for isolated nodes (self-edges only) overflows at once:
    # the rollout must reallocate and agree.
    n = len(sim.types)
    sim.nbrs = graph.allocate(sim.spec, graph.parking_positions(n, sim.spec))
    small = sim.nbrs.idx.shape[-1]
    np.testing.assert_allclose(sim.rollout(p.initial()), ample, atol=1e-6)
    self.assertGreater(sim.nbrs.idx.shape[-1], small)


class OptimiseTest(absltest.TestCase):

  def test_projected_adam_stays_in_range_and_logs(self):
    p = design.Placement(scene(num_frames=20), x_range=(1.25, 1.3))
    sim = design.MPMRollout(p)
    obj = objectives.make("centroid", target_x=0.0)  # push the sand far
    records = []
    history = design.optimise(sim, obj.smooth, p.initial(), steps=4,
                              learning_rate=0.2, log=records.append)
    self.assertEqual(records, history)
    self.assertLen(history, 4)
    xs = [r["x"] for r in history]
    self.assertTrue(all(1.25 - 1e-6 <= x <= 1.3 + 1e-6 for x in xs), xs)
    # Steps larger than the range land on a bound.
    self.assertTrue(any(min(abs(x - 1.25), abs(x - 1.3)) < 1e-6
                        for x in xs[1:]), xs)


if __name__ == "__main__":
  absltest.main()
