"""Tests for `mpm.incline`: the periodic strip and the Bagnold profile."""

import math

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mpm import constitutive
from mpm import incline
from mpm import scene as scene_lib
from mpm import simulation
from mpm import solver
from mpm import transfer

MU_I = {"rheology": "mu_i", "grain_diameter": 0.002}


def _material(**kw) -> scene_lib.Material:
  return incline.strip_scene(0.02, material={**MU_I, **kw}).material


class BagnoldFormulaTest(absltest.TestCase):

  def test_the_profile_obeys_the_local_law_at_every_depth(self):
    # From u(z) alone: the shear rate du/dz and the lithostatic pressure
    # give back, through the rheology's own mu(I), the stress ratio
    # tan(theta) that steady uniform flow requires.
    m = _material()
    depth, theta = 0.02, math.radians(34.0)
    z = np.linspace(0.001, 0.019, 19)
    dz = 1e-6
    rate = (incline.bagnold_velocity(z + dz, depth, theta, m) -
            incline.bagnold_velocity(z - dz, depth, theta, m)) / (2 * dz)
    p = m.density * 9.81 * math.cos(theta) * (depth - z)
    i = rate * m.grain_diameter / np.sqrt(p / m.grain_density)
    mu = np.asarray(constitutive.mu_of_i(i, constitutive.MuI(
        mu_s=m.mu_s, mu_2=m.mu_2, I_0=m.I_0, grain_diameter=m.grain_diameter,
        grain_density=m.grain_density)))
    np.testing.assert_allclose(mu, math.tan(theta), rtol=1e-5)
    self.assertEqual(incline.bagnold_velocity(0.0, depth, theta, m), 0.0)

  def test_no_steady_flow_outside_mu_s_mu_2(self):
    m = _material()
    self.assertTrue(math.isnan(incline.inertial_number(
        math.atan(m.mu_s) - 0.01, m)))
    self.assertTrue(math.isnan(incline.inertial_number(
        math.atan(m.mu_2) + 0.01, m)))


class PeriodicStripTest(absltest.TestCase):

  def test_stencils_wrap_around_the_strip(self):
    spec = transfer.GridSpec(0.01, (5, 4), (0.0, -0.02), periodic_x=True)
    x = jnp.asarray([[0.001, 0.0], [0.044, 0.0], [0.02, 0.0]], jnp.float32)
    st = transfer.stencil(x, spec)
    columns = np.asarray(st.index) // spec.shape[1]
    self.assertEqual(sorted(set(columns[0])), [0, 1, 4])   # left edge
    self.assertEqual(sorted(set(columns[1])), [0, 3, 4])   # right edge
    self.assertEqual(sorted(set(columns[2])), [1, 2, 3])
    # All of the mass lands on the grid, none past its ends.
    grid = transfer.p2g(st, jnp.ones(3), jnp.zeros((3, 2)),
                        jnp.zeros((3, 2, 2)), spec.n_nodes)
    self.assertAlmostEqual(float(grid[:, 2].sum()), 3.0, places=5)

  def test_a_shift_along_the_strip_changes_nothing(self):
    # No wall anywhere along x: the same layer shifted by 3 cells (wrapped)
    # moves as the unshifted one, shifted.
    strip = incline.periodic_setup(
        incline.strip_scene(0.01, width=0.008, material=MU_I), 34.0)
    s = strip.setup
    width = s.scene.domain.width
    step = jax.jit(lambda st: solver.advance(st, s.params, s.field, s.spec,
                                             200)[0])
    shift = 3 * s.spec.dx
    moved = s.state.replace(x=s.state.x.at[:, 0].set(
        jnp.mod(s.state.x[:, 0] + shift, width)))
    a, b = step(s.state), step(moved)
    dx = np.mod(np.asarray(b.x[:, 0] - a.x[:, 0]) - shift + width / 2,
                width) - width / 2
    np.testing.assert_allclose(dx, 0.0, atol=2e-6)
    np.testing.assert_allclose(b.x[:, 1], a.x[:, 1], atol=2e-6)
    np.testing.assert_allclose(b.v, a.v, atol=2e-4)
    self.assertGreater(float(jnp.abs(a.v[:, 0]).max()), 0.005)  # it flows

  def test_bad_strips_are_refused(self):
    with self.assertRaisesRegex(ValueError, "multiple of dx"):
      incline.strip_scene(0.02, width=0.0105)
    with self.assertRaisesRegex(ValueError, "at least 4 cells"):
      incline.strip_scene(0.002)
    with self.assertRaisesRegex(ValueError, "0 < theta < 90"):
      incline.periodic_setup(incline.strip_scene(0.02), 95.0)


class SteadyFlowTest(absltest.TestCase):

  @pytest.mark.slow  # 3 s of flow, 170,000 substeps: 2.5 min at -O0
  def test_mu_i_flows_steadily_at_the_bagnold_profile(self):
    # 2 cm of sand on a rough base at 34 deg (I = 0.18), a grid of 1 mm:
    # the surface speed settles within 5% of the analytic one (measured
    # 3%, docs/physics.md), and so does the profile below it.
    strip = incline.periodic_setup(
        incline.strip_scene(0.02, width=0.005, material=MU_I), 34.0)
    times, speeds, final = incline.run(strip, 3.0, frame_dt=0.1)
    m = strip.setup.scene.material
    expected = incline.bagnold_velocity(0.95 * strip.depth, strip.depth,
                                        strip.theta, m)
    self.assertAlmostEqual(speeds[-1] / expected, 1.0, delta=0.05)
    self.assertLess(abs(speeds[-1] / speeds[-6] - 1), 0.01)   # steady
    z = np.asarray(final.x[:, 1]) - incline.FLOOR
    u = np.asarray(final.v[:, 0])
    for k in range(10):
      band = (z >= k * 0.002) & (z < (k + 1) * 0.002)
      analytic = incline.bagnold_velocity((k + 0.5) * 0.002, strip.depth,
                                          strip.theta, m)
      self.assertLess(abs(u[band].mean() - analytic), 0.1 * expected, k)
    del times

  def test_drucker_prager_accelerates_past_its_friction(self):
    # Constant friction has no steady flow on a slope steeper than it
    # (sin(35 deg) = 0.57: 29.8 deg): the layer keeps gaining speed at about
    # a sliding block's g (sin(theta) - mu cos(theta)) = 0.82 m/s^2
    # (measured 0.91).
    strip = incline.periodic_setup(incline.strip_scene(0.01, width=0.004),
                                   34.0)
    _, speeds, _ = incline.run(strip, 0.4, frame_dt=0.1)
    theta, mu = strip.theta, math.sin(math.radians(35.0))
    block = 9.81 * (math.sin(theta) - mu * math.cos(theta))
    self.assertTrue(np.all(np.diff(speeds) > 0))
    self.assertAlmostEqual((speeds[-1] - speeds[0]) / 0.3 / block, 1.0,
                           delta=0.25)
    # Past the speed its substep was sized for, the run stops and says so.
    with self.assertRaisesRegex(simulation.SimulationError,
                                "past max_speed = 0.2 m/s"):
      incline.run(strip, 0.4, frame_dt=0.1, max_speed=0.2)


if __name__ == "__main__":
  absltest.main()
