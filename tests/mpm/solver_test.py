"""Tests for `mpm.solver` (through `mpm.simulate` on small scenes)."""

import contextlib
import functools
import math

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mpm
from mpm import boundary
from mpm import geometry
from mpm import scene as scene_lib
from mpm import solver
from mpm import transfer

G = 9.81
FLOOR = 0.05  # height of the flat floor [m]

_SOLID_SDF = jax.jit(geometry.solid_sdf)
_ROLLOUT = jax.jit(solver.rollout, static_argnums=(3, 4, 5))
_OBSTACLE_SDF = jax.jit(geometry.obstacle_sdf)


def _flat_scene(width, height, box, spacing, dx, **kw):
  d = {"name": "flat", "domain": {"width": width, "height": height},
       "ramp": {"kind": "polynomial", "coefficients": [FLOOR]},
       "granular": {"box": list(box), "spacing": spacing},
       "material": {"density": 1500.0, "youngs_modulus": 1e5,
                    "poisson_ratio": 0.3, "friction_angle_deg": 35.0},
       "solver": {"dx": dx, "cfl": 0.4}}
  d.update(kw)
  return mpm.Scene.from_dict(d)


def _lattice(x0, x1, y0, y1, spacing):
  """Cell-centred lattice points of [x0, x1] x [y0, y1], float32 [N, 2]."""
  xs = x0 + spacing * (np.arange(round((x1 - x0) / spacing)) + 0.5)
  ys = y0 + spacing * (np.arange(round((y1 - y0) / spacing)) + 0.5)
  return np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2).astype(np.float32)


def _run(scene, x0=None):
  return mpm.simulate_setups([mpm.setup(scene, x0)])[0]


@contextlib.contextmanager
def _count_lowerings():
  """Counts programs lowered to MLIR (each jit cache miss lowers once)."""
  events = []

  def listener(event, duration, **_):
    del duration
    if event == "/jax/core/compile/jaxpr_to_mlir_module_duration":
      events.append(event)

  jax.monitoring.register_event_duration_secs_listener(listener)
  try:
    yield events
  finally:
    jax.monitoring.unregister_event_duration_listener(listener)


# ------------------------------------------------------------ incline ------

THETA_DEG = 30.0
INCLINE_W = 0.4


def _incline_scene(mu, frame_dt=0.01, num_frames=21):
  """A 30 degree polyline incline; sand of friction angle 60 > 30 degrees."""
  theta = math.radians(THETA_DEG)
  y_top = FLOOR + INCLINE_W * math.tan(theta)
  return mpm.Scene.from_dict({
      "name": f"incline_mu{mu}",
      "domain": {"width": INCLINE_W, "height": y_top + 0.1},
      "ramp": {"kind": "polyline",
               "points": [[0.0, y_top], [INCLINE_W, FLOOR]]},
      "granular": {"box": [0.06, 0.0, 0.14, y_top + 0.1], "spacing": 0.005},
      "material": {"density": 1500.0, "youngs_modulus": 1e5,
                   "poisson_ratio": 0.3, "friction_angle_deg": 60.0},
      "boundary_friction": mu,
      "solver": {"dx": 0.01, "cfl": 0.4},
      "num_frames": num_frames, "frame_dt": frame_dt})


def _incline_particles(scene, start=0.07, length=0.09, depth=0.025,
                       spacing=0.005):
  """A slab on the incline: a lattice aligned with the slope, touching it."""
  theta = math.radians(THETA_DEG)
  tangent = np.array([math.cos(theta), -math.sin(theta)])
  normal = np.array([math.sin(theta), math.cos(theta)])
  s = start + spacing * (np.arange(round(length / spacing)) + 0.5)
  n = spacing * (np.arange(round(depth / spacing)) + 0.5)
  s, n = (a.reshape(-1, 1) for a in np.meshgrid(s, n))
  top = np.array([0.0, scene.ramp.height(0.0)])
  return (top + s * tangent + n * normal).astype(np.float32)


def _along_slope(positions):
  theta = math.radians(THETA_DEG)
  return positions @ np.array([math.cos(theta), -math.sin(theta)])


class MassTest(absltest.TestCase):

  def test_particles_and_grid_mass_are_conserved(self):
    scene = _flat_scene(0.3, 0.3, (0.05, 0.1, 0.25, 0.2), 0.01, 0.02,
                        obstacles=[{"shape": "semicircle", "x": 0.15,
                                    "radius": 0.04}],
                        num_frames=11, frame_dt=0.01)
    s = mpm.setup(scene)
    final, positions, _, finite = _ROLLOUT(
        s.state, s.params, s.field, s.spec, 10, s.n_substeps)
    self.assertTrue(np.all(finite))
    self.assertEqual(positions.shape, (10,) + s.state.x.shape)
    # Particle volumes (and so masses) never change.
    np.testing.assert_array_equal(final.volume, s.state.volume)
    # All of the particles' mass lands on the grid, also next to the solids.
    mass = s.params.density * final.volume
    st = transfer.stencil(final.x, s.spec)
    grid = transfer.p2g(st, mass, jnp.zeros_like(final.x),
                        jnp.zeros_like(final.C), s.spec.n_nodes)
    np.testing.assert_allclose(np.sum(grid[:, 2]), np.sum(mass), rtol=1e-5,
                               atol=0)
    # The sand moved (it hit the obstacle), so the check is not vacuous.
    self.assertGreater(np.max(np.abs(final.x - s.state.x)), 0.01)

  def test_particle_count_never_changes(self):
    scene = _flat_scene(0.3, 0.3, (0.05, 0.1, 0.25, 0.2), 0.01, 0.02,
                        num_frames=6, frame_dt=0.01)
    result = mpm.simulate(scene)
    n = len(mpm.granular_particles(scene))
    self.assertEqual(result.positions.shape, (6, n, 2))
    self.assertTrue(np.all(np.isfinite(result.positions)))


class FreeFallTest(absltest.TestCase):

  def test_follows_gravity_before_contact(self):
    # A block 20 cm above the floor falls 4.9 cm in 0.1 s: no contact.
    scene = _flat_scene(0.3, 0.4, (0.1, 0.25, 0.2, 0.33), 0.01, 0.02,
                        num_frames=11, frame_dt=0.01)
    result = mpm.simulate(scene)
    p = result.positions.astype(np.float64)
    t = 0.01 * np.arange(11)
    dt = scene.frame_dt / result.n_substeps
    drop = p[0, :, 1] - p[:, :, 1]                       # [T, N]
    # Semi-implicit Euler (v += g dt, then x += v dt) falls
    # g dt^2 n (n + 1) / 2 after n substeps: g t^2 / 2 + g t dt / 2.
    n = t / dt
    np.testing.assert_allclose(drop, np.broadcast_to(
        (G * dt**2 * n * (n + 1) / 2)[:, None], drop.shape), atol=2e-5,
                               rtol=0)  # float32 positions of O(0.3) m
    # ... which is g t^2 / 2 to within g t dt (first order in dt).
    err = np.abs(drop - (G * t**2 / 2)[:, None])
    self.assertTrue(np.all(err <= (G * t * dt)[:, None] + 2e-5))
    # No horizontal motion (and, as every particle drops the same, no
    # deformation).
    np.testing.assert_allclose(p[:, :, 0], np.broadcast_to(p[0, :, 0],
                                                           p.shape[:2]),
                               atol=1e-6, rtol=0)
    self.assertGreater(np.min(p[-1, :, 1]), FLOOR + 0.1)


@functools.lru_cache(maxsize=None)
def _resting_layer():
  """A 4 cm layer on the floor spanning the box wall to wall, for 1.5 s.

  Wall to wall, it has no free sides (which would slump to the angle of
  repose); it starts on the floor, on its lattice.
  """
  width, spacing = 0.2, 0.005
  scene = _flat_scene(width, 0.2, (0.0, FLOOR, width, FLOOR + 0.04),
                      spacing, 0.01, num_frames=31, frame_dt=0.05)
  x0 = _lattice(0.0, width, FLOOR, FLOOR + 0.04, spacing)
  return scene, x0, _run(scene, x0).positions


class RestTest(absltest.TestCase):

  SETTLE = 10  # frames of 0.05 s

  def test_layer_on_floor_stays_at_rest(self):
    # After 0.5 s of settling (elastic compression under its own weight,
    # ~0.1 mm) the layer must not drift: < 1 mm over the next second.
    scene, x0, p = _resting_layer()
    p = p[self.SETTLE:]
    drift = np.max(np.linalg.norm(p - p[0], axis=-1))
    self.assertLess(drift, 1e-3,
                    f"resting layer drifts {drift * 1e3:.2f} mm in 1 s")
    # Settling itself is small: the layer starts where it should rest.
    self.assertLess(np.max(np.abs(p[0] - x0)), 0.5 * scene.dx)

  def test_walls_hold_the_layer(self):
    # The layer presses sideways on the walls (K0 ~ 0.4 of its weight). A
    # wall that gives (a half-weighted node on it) lets the sand creep into
    # it, ~1.2 mm/s at the edges; a rigid one holds it to elastic strain.
    _, x0, p = _resting_layer()
    creep = np.max(np.abs(p[self.SETTLE:, :, 0] - p[self.SETTLE, :, 0]))
    self.assertLess(creep, 1e-4, f"sand creeps {creep * 1e3:.2f} mm into "
                    "the walls in 1 s")
    self.assertLess(np.max(np.abs(p[:, :, 0] - x0[:, 0])), 1e-4)


class SlidingLayerTest(parameterized.TestCase):
  """A sand layer launched at v0 along a floor of friction mu stops after
  v0^2 / (2 mu g): the floor's friction, acting through grid nodes, must not
  depend on the layer's thickness in cells (the front of a deposit is a
  layer a cell or two thick)."""

  V0, MU = 1.0, 0.3

  def _travel(self, thickness, spacing):
    """Centre-of-mass travel [T] (m) after each 10 ms frame."""
    # Lifted 0.1 mm: the lowest lattice row then lies a half spacing clear.
    base = FLOOR + 1e-4
    scene = _flat_scene(0.7, FLOOR + thickness + 0.05,
                        (0.05, base, 0.15, base + thickness), spacing,
                        2 * spacing, boundary_friction=self.MU,
                        num_frames=61, frame_dt=0.01)
    s = mpm.setup(scene)
    launched = s.state.replace(v=s.state.v.at[:, 0].set(self.V0))
    _, positions, _, finite = _ROLLOUT(launched, s.params, s.field, s.spec,
                                       60, s.n_substeps)
    self.assertTrue(np.all(finite))
    x = np.asarray(positions)[:, :s.n_particles, 0].astype(np.float64)
    return x.mean(-1) - np.asarray(s.state.x)[:s.n_particles, 0].mean()

  @parameterized.parameters((0.01, 0.005), (0.005, 0.0025))
  def test_layer_a_cell_thick_stops_after_the_coulomb_distance(
      self, thickness, spacing):
    # One cell thick on a 1 cm and on a 5 mm grid; it slides as a block.
    travel = self._travel(thickness, spacing)
    # The stop takes v0 / (mu g) = 0.34 s; 0.6 s are simulated.
    np.testing.assert_allclose(travel[-1], self.V0**2 / (2 * self.MU * G),
                               rtol=0.03)
    self.assertLess(abs(travel[-1] - travel[-10]), 1e-4)   # at rest

  def test_thick_layer_travels_as_far_on_a_finer_grid(self):
    # A 4 cm layer spreads while it slows (its front runs on after its rear
    # stops, where static friction is below mu N), so its centre travels at
    # least the Coulomb distance; on a twice finer grid, as far.
    coarse, fine = (self._travel(0.04, s)[-1] for s in (0.005, 0.0025))
    self.assertGreater(coarse, 0.99 * self.V0**2 / (2 * self.MU * G))
    np.testing.assert_allclose(fine, coarse, rtol=0.02)


class InclineTest(parameterized.TestCase):
  """A sand slab on a 30 degree incline with Coulomb friction mu at its base.

  The slab's material (friction angle 60 degrees) is stronger than the
  slope, so it slides (tan 30 = 0.58 > mu) or sticks (mu > 0.58) as a whole;
  only its free ends may slump.
  """

  def _slide(self, mu):
    scene = _incline_scene(mu)
    p = _run(scene, _incline_particles(scene)).positions.astype(np.float64)
    theta = math.radians(THETA_DEG)
    a_ref = G * (math.sin(theta) - mu * math.cos(theta))
    t = scene.frame_dt * np.arange(len(p))
    s = _along_slope(p).mean(-1)
    # Only external forces set the centre of mass's acceleration: fit
    # s(t) = s0 + v0 t + a t^2 / 2 over 0.2 s.
    a = 2 * np.polyfit(t, s, 2)[0]
    self.assertLess(np.max(p[..., 0]), INCLINE_W - 0.05)  # far from the wall
    return a, a_ref

  @parameterized.parameters(0.0, 0.15, 0.3)
  def test_slides_at_coulomb_acceleration(self, mu):
    a, a_ref = self._slide(mu)
    np.testing.assert_allclose(a, a_ref, rtol=0.03, atol=0)

  @pytest.mark.xfail(strict=True, reason=(
      "solver: friction falls short of mu N as mu nears tan(theta): at "
      "mu = 0.45 the slab accelerates 6% faster than g (sin - mu cos) "
      "(mu = 0.5: 21%). Measured on the grid: the slab thins, so the "
      "normal impulse is only 95-98% of M g cos(theta) t, and nodes that "
      "stick (light nodes with a large normal velocity) give 1-6% less "
      "than mu times their normal impulse. Full solid weights at phi <= 0 "
      "(boundary._weight) halved the error, to 3.2%."))
  def test_slides_at_coulomb_acceleration_near_critical_friction(self):
    a, a_ref = self._slide(0.45)
    np.testing.assert_allclose(a, a_ref, rtol=0.03, atol=0)

  @pytest.mark.xfail(strict=True, reason=(
      "solver: sand creeps down a slope it should stick to (mu = 0.8 > "
      "tan 30 = 0.58): in 0.4 s the base row slips 4 mm on average and the "
      "centre of mass moves 12.6 mm, 3.8 mm of it in the last 0.2 s (with "
      "mu = 1.5 still 2.6 mm and 8.8 mm). Boundary nodes in the soft band "
      "(-dx/2 < phi < dx/2) remove only a fraction w < 1 of a stuck "
      "velocity, so a sustained load leaks through them. Since solid "
      "weights are full at phi <= 0 (boundary._weight) the base holds, but "
      "the centre of mass still creeps 1.7 mm in the last 0.2 s."))
  def test_sticks_when_friction_exceeds_slope(self):
    mu = 0.8
    scene = _incline_scene(mu, frame_dt=0.02, num_frames=21)
    x0 = _incline_particles(scene)
    s = _along_slope(_run(scene, x0).positions.astype(np.float64))
    # The base row must not slide, and once the slab's ends have slumped
    # (0.2 s) its centre of mass must be at rest. (Sliding with mu = 0.3
    # would cover 4.7 cm in 0.2 s.)
    base = np.argsort(x0 @ np.array([0.5, math.sqrt(3) / 2]))[:18]
    base_slip = np.max(np.abs(s[:, base].mean(-1) - s[0, base].mean()))
    self.assertLess(base_slip, 1e-3, f"base slides {base_slip * 1e3:.2f} mm")
    com = s.mean(-1)
    late = com[-1] - com[10]
    self.assertLess(abs(late), 1e-3,
                    f"centre of mass creeps {late * 1e3:.2f} mm in 0.2 s")


class PenetrationTest(parameterized.TestCase):

  def test_sand_stays_out_of_ramp_and_obstacles(self):
    # Sand poured onto an incline with one obstacle of each shape.
    dx = 0.01
    scene = mpm.Scene.from_dict({
        "name": "penetration", "domain": {"width": 0.4, "height": 0.4},
        "ramp": {"kind": "polyline", "points": [[0.0, 0.2], [0.4, 0.05]]},
        "obstacles": [
            {"shape": "semicircle", "x": 0.1, "radius": 0.03},
            {"shape": "rectangle", "x": 0.2, "width": 0.03, "height": 0.05},
            {"shape": "triangle", "x": 0.31, "base": 0.04, "height": 0.05}],
        "granular": {"box": [0.05, 0.26, 0.35, 0.29], "spacing": 0.005},
        "material": {"density": 1500.0, "youngs_modulus": 1e5,
                     "poisson_ratio": 0.3, "friction_angle_deg": 35.0},
        "boundary_friction": 0.3,
        "solver": {"dx": dx, "cfl": 0.4},
        "num_frames": 26, "frame_dt": 0.01})
    p = jnp.asarray(mpm.simulate(scene).positions)
    ramp = geometry.ramp_params(scene.ramp)
    obstacles = tuple(geometry.obstacle_params(o) for o in scene.obstacles)
    phi = np.asarray(_SOLID_SDF(ramp, obstacles, p))
    # The sand reached every obstacle (else the test proves nothing) ...
    for i, o in enumerate(obstacles):
      self.assertLess(float(jnp.min(_OBSTACLE_SDF(ramp, o, p))), dx,
                      f"sand never reached obstacle {i}")
    # ... and never went more than half a cell into them or the ramp.
    worst = np.unravel_index(np.argmin(phi), phi.shape)
    self.assertGreater(np.min(phi), -0.5 * dx,
                       f"penetration {-np.min(phi) * 1e3:.2f} mm at frame "
                       f"{worst[0]}, x = {p[worst]}")


class RecompilationTest(absltest.TestCase):

  def test_second_call_with_same_shapes_does_not_compile(self):
    def scene(phi, mu, name):
      return _flat_scene(0.3, 0.3, (0.1, 0.1, 0.2, 0.15), 0.01, 0.02,
                         num_frames=4, frame_dt=0.01, name=name,
                         boundary_friction=mu,
                         material={"density": 1500.0, "youngs_modulus": 1e5,
                                   "poisson_ratio": 0.3,
                                   "friction_angle_deg": phi})

    first = mpm.simulate(scene(35.0, 0.5, "first"))
    with _count_lowerings() as lowerings:
      second = mpm.simulate(scene(25.0, 0.2, "second"))
    self.assertEqual(second.compile_time_s, 0.0)
    self.assertEmpty(lowerings)
    self.assertEqual(first.positions.shape, second.positions.shape)


class GradientTest(parameterized.TestCase):
  """jax.grad w.r.t. an obstacle's x and the friction angle, against central
  differences.

  A slab on a 30 degree incline pushes against a rectangle. The final
  positions are piecewise smooth in both parameters (contact, stick/slip and
  return-mapping branches switch), with kinks ~1e-3 apart after 0.1 s:
  differences with h = 1e-3 are off by ~5%. With h = 1e-5 in float64 they
  resolve the local derivative and agree with jax.grad to rtol 1e-4.
  """

  def _problem(self):
    theta = math.radians(30.0)
    width, y_low = 0.3, FLOOR
    y_top = y_low + width * math.tan(theta)
    scene = mpm.Scene.from_dict({
        "name": "gradient", "domain": {"width": width, "height": y_top + 0.06},
        "ramp": {"kind": "polyline", "points": [[0, y_top], [width, y_low]]},
        "obstacles": [{"shape": "rectangle", "x": 0.186, "width": 0.04,
                       "height": 0.05}],
        "granular": {"box": [0.08, 0.0, 0.165, y_top + 0.06],
                     "spacing": 0.01},
        "material": {"density": 1500.0, "youngs_modulus": 2e4,
                     "poisson_ratio": 0.3, "friction_angle_deg": 40.0},
        "boundary_friction": 0.2, "solver": {"dx": 0.02, "cfl": 0.4},
        "num_frames": 11, "frame_dt": 0.01})
    x0 = mpm.granular_particles(scene)
    x0 = x0[x0[:, 1] - scene.ramp.height(x0[:, 0]) < 0.03]
    s = mpm.setup(scene, x0, particle_bucket=1, node_bucket=1)
    f64 = lambda tree: jax.tree.map(
        lambda a: a.astype(jnp.float64)
        if jnp.issubdtype(a.dtype, jnp.floating) else a, tree)
    ramp = f64(geometry.ramp_params(scene.ramp))
    obstacle = f64(geometry.obstacle_params(scene.obstacles[0]))
    state, params = f64(s.state), f64(s.params)

    def final_state(obstacle_x, friction_angle, n_substeps=None, F=None):
      """After the scene's 10 frames, or after n_substeps single substeps
      from an elastic deformation F."""
      # The field is built inside: it depends on the obstacle's x.
      field = boundary.make_field(s.spec, s.field.index, width,
                                  scene.domain.height, ramp,
                                  (obstacle.replace(x=obstacle_x),))
      p = params.replace(friction_angle=friction_angle)
      if n_substeps is None:
        final, _, _, _ = solver.rollout(state, p, field, s.spec,
                                        scene.num_frames - 1, s.n_substeps)
        return final
      st = state.replace(F=jnp.broadcast_to(F, state.F.shape))
      for _ in range(n_substeps):
        st, _ = solver.substep(st, p, field, s.spec)
      return st

    args = (jnp.float64(scene.obstacles[0].x),
            jnp.float64(math.radians(scene.material.friction_angle_deg)))
    return final_state, args

  def _check(self, loss, x, phi, h, rtol):
    grad_x, grad_phi = jax.jit(jax.grad(loss, argnums=(0, 1)))(x, phi)
    f = jax.jit(loss)
    fd_x = (f(x + h, phi) - f(x - h, phi)) / (2 * h)
    fd_phi = (f(x, phi + h) - f(x, phi - h)) / (2 * h)
    grads = np.array([grad_x, grad_phi], np.float64)
    fds = np.array([fd_x, fd_phi], np.float64)
    self.assertTrue(np.all(np.isfinite(grads)))
    np.testing.assert_allclose(grads, fds, rtol=rtol, atol=0)
    return grads

  def test_one_substep_matches_central_differences(self):
    # One substep: smooth, so a tight tolerance holds, and cheaper to compile
    # (the rollout's gradient is the slow test). The sand starts sheared
    # beyond the cone, so the return mapping depends on the friction angle.
    with jax.enable_x64(True):
      final_state, (x, phi) = self._problem()
      sheared = jnp.array([[0.99, 0.2], [0.0, 0.99]])

      def loss(x, phi):
        st = final_state(x, phi, 1, sheared)
        return jnp.sum(st.x) + jnp.sum(st.F)

      grads = self._check(loss, x, phi, h=1e-6, rtol=1e-5)
    # Both parameters matter (contact with the obstacle, plastic flow).
    self.assertTrue(np.all(np.abs(grads) > 1e-6), grads)

  @pytest.mark.slow  # ~30 s cold: compiling the gradient of the rollout
  def test_rollout_matches_central_differences(self):
    with jax.enable_x64(True):
      final_state, (x, phi) = self._problem()
      loss = lambda x, phi: jnp.mean(final_state(x, phi).x[:, 0])
      grads = self._check(loss, x, phi, h=1e-5, rtol=1e-4)
    # Moving the obstacle downhill lets the slab go further.
    self.assertGreater(grads[0], 0.05)


class SlopeTest(parameterized.TestCase):
  """A layer 5 cm thick filling a box 30 cm long, gravity tilted by theta:
  an infinite slope is at rest while tan(theta) <= mu_s (the sand's
  friction at rest, sin(35 deg) = 0.57 for both rheologies: 29.8 deg) and
  flows once tan(theta) passes mu_2 (mu(I): 0.83, 39.8 deg)."""

  def _end_speed(self, theta_deg, rheology, friction_angle_deg=35.0):
    """Mean particle speed (m/s) over the last 10 ms of 0.4 s."""
    scene = _flat_scene(
        0.3, 0.2, (0.0, FLOOR + 1e-4, 0.3, FLOOR + 0.05), 0.005, 0.01,
        boundary_friction=2.0, num_frames=41, frame_dt=0.01)
    d = scene.to_dict()
    d["material"]["friction_angle_deg"] = friction_angle_deg
    scene = scene_lib.with_rheology(mpm.Scene.from_dict(d), rheology)
    s = mpm.setup(scene)
    theta = math.radians(theta_deg)
    params = s.params.replace(gravity=jnp.asarray(
        [G * math.sin(theta), -G * math.cos(theta)], jnp.float32))
    _, positions, _, finite = _ROLLOUT(s.state, params, s.field, s.spec,
                                       40, s.n_substeps)
    self.assertTrue(np.all(finite))
    x = np.asarray(positions)[-2:, :s.n_particles]
    return float(np.linalg.norm(x[1] - x[0], axis=-1).mean() / 0.01)

  @parameterized.product(
      theta_deg=(15.0, 25.0),
      rheology=("drucker_prager", "mu_i", "mu_i_compressible"))
  def test_below_mu_s_the_slope_rests(self, theta_deg, rheology):
    # What is left is elastic settling, millimetres per second.
    self.assertLess(self._end_speed(theta_deg, rheology), 0.01)

  @parameterized.parameters("drucker_prager", "mu_i", "mu_i_compressible")
  def test_above_mu_2_the_slope_flows(self, rheology):
    self.assertGreater(self._end_speed(45.0, rheology), 0.05)

  def test_regularized_below_mu_s_creeps_imperceptibly_and_flows_above(self):
    """Barker & Gray's law has no yield stress, but at tan 15 deg = 0.27
    against mu_s = sin 22.5 deg = 0.38 its rate, I = A exp(-alpha / mu^2)
    ~ 1e-8, is nothing a run sees; at 45 deg it flows. (The default sand,
    35 deg, has no well-posed range to regularise below.)"""
    self.assertLess(self._end_speed(15.0, "mu_i_regularized", 22.5), 0.01)
    self.assertGreater(self._end_speed(45.0, "mu_i_regularized", 22.5), 0.05)


class CompressibleTest(absltest.TestCase):
  """The compressible mu(I) in a scene: a column collapsing on a floor."""

  def _run(self, **material):
    d = _flat_scene(0.3, 0.2, (0.02, FLOOR + 1e-4, 0.08, FLOOR + 0.06),
                    0.005, 0.01, boundary_friction=0.7, num_frames=31,
                    frame_dt=0.01).to_dict()
    d["material"].update(rheology="mu_i_compressible", **material)
    s = mpm.setup(mpm.Scene.from_dict(d))
    final, positions, _, finite = _ROLLOUT(s.state, s.params, s.field,
                                           s.spec, 30, s.n_substeps)
    self.assertTrue(np.all(finite))
    return s, final, np.asarray(positions)

  def test_volume_fraction_stays_physical_and_masses_fixed(self):
    s, final, positions = self._run()
    n = s.n_particles
    phi = np.asarray(final.volume_fraction)
    np.testing.assert_allclose(s.state.volume_fraction, 0.6)
    self.assertTrue(np.all((phi > 0) & (phi <= 1)))
    # The flowing sand's phi moved (the check is not vacuous) but its bulk
    # stays near the packing it started at.
    self.assertGreater(np.abs(phi[:n] - 0.6).max(), 1e-3)
    self.assertBetween(float(np.median(phi[:n])), 0.5, 0.62)
    np.testing.assert_array_equal(final.volume, s.state.volume)
    # Padding particles keep theirs.
    np.testing.assert_array_equal(phi[n:], s.state.volume_fraction[n:])
    self.assertGreater(np.abs(positions[-1, :n, 0] - s.state.x[:n, 0]).max(),
                       0.01)

  def test_without_dilatancy_the_run_is_mu_i(self):
    """K = 0: the positions of mu(I)'s run, within float32 rounding (the two
    programs are fused differently; section 12 of docs/physics.md)."""
    _, _, compressible = self._run(dilatancy=0.0)
    d = _flat_scene(0.3, 0.2, (0.02, FLOOR + 1e-4, 0.08, FLOOR + 0.06),
                    0.005, 0.01, boundary_friction=0.7, num_frames=31,
                    frame_dt=0.01).to_dict()
    d["material"]["rheology"] = "mu_i"
    s = mpm.setup(mpm.Scene.from_dict(d))
    self.assertIsNone(s.state.volume_fraction)
    _, plain, _, _ = _ROLLOUT(s.state, s.params, s.field, s.spec, 30,
                              s.n_substeps)
    np.testing.assert_allclose(compressible, np.asarray(plain), rtol=0,
                               atol=1e-4)

  def test_differentiable_and_vmappable(self):
    """Two substeps from a sheared state: gradients w.r.t. the dilatancy K
    and the volume fraction phi match central differences (float64), and
    a vmap over K gives each K's own substep."""
    d = _flat_scene(0.3, 0.2, (0.02, FLOOR + 1e-4, 0.08, FLOOR + 0.06),
                    0.01, 0.02).to_dict()
    d["material"]["rheology"] = "mu_i_compressible"
    s = mpm.setup(mpm.Scene.from_dict(d), particle_bucket=1, node_bucket=1)
    sheared = jnp.array([[0.99, 0.1], [0.0, 0.99]])  # beyond mu_s
    with jax.enable_x64(True):
      f64 = lambda tree: jax.tree.map(
          lambda a: a.astype(jnp.float64)
          if jnp.issubdtype(a.dtype, jnp.floating) else a, tree)
      state, params, field = f64(s.state), f64(s.params), f64(s.field)
      state = state.replace(F=jnp.broadcast_to(sheared, state.F.shape))

      def loss(k, phi):
        p = params.replace(mu_i=params.mu_i.replace(dilatancy=k))
        st = state.replace(volume_fraction=jnp.full_like(state.volume, phi))
        for _ in range(2):
          st, _ = solver.substep(st, p, field, s.spec)
        return jnp.sum(st.x) + jnp.sum(st.F)

      k, phi, h = jnp.float64(4.09), jnp.float64(0.58), 1e-6
      grads = np.array(jax.jit(jax.grad(loss, argnums=(0, 1)))(k, phi))
      f = jax.jit(loss)
      fds = np.array([(f(k + h, phi) - f(k - h, phi)) / (2 * h),
                      (f(k, phi + h) - f(k, phi - h)) / (2 * h)])
    self.assertTrue(np.all(np.isfinite(grads)))
    self.assertTrue(np.all(np.abs(grads) > 1e-6), grads)
    np.testing.assert_allclose(grads, fds, rtol=1e-4, atol=0)

    state = s.state.replace(F=jnp.broadcast_to(sheared, s.state.F.shape))

    def step(k):
      p = s.params.replace(mu_i=s.params.mu_i.replace(dilatancy=k))
      return solver.substep(state, p, s.field, s.spec)[0].F

    ks = jnp.asarray([0.0, 4.09], jnp.float32)
    batched = jax.jit(jax.vmap(step))(ks)
    for i, k in enumerate(ks):
      np.testing.assert_allclose(batched[i], jax.jit(step)(k), rtol=0,
                                 atol=1e-6)
    self.assertGreater(float(jnp.abs(batched[1] - batched[0]).max()), 1e-5)


if __name__ == "__main__":
  absltest.main()
