"""Tests for `mpm.constitutive`."""

import math

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

from mpm import constitutive

E, NU = 3.537e5, 0.3  # the paper's sand [Pa]
MU, LAM = constitutive.lame_parameters(E, NU)

# Jitted once each: eager dispatch of their many small ops is slow.
_project = jax.jit(constitutive.project)
_project_principal = jax.jit(constitutive.project_principal)
_stress = jax.jit(constitutive.kirchhoff_stress)
_log_strain = jax.jit(constitutive.log_strain)


def _rotation(angle):
  c, s = np.cos(angle), np.sin(angle)
  return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _random_f(rng, n, log_mean=(-0.05, 0.03), log_spread=0.06):
  """F = R(a) diag(exp(e)) R(b): random rotations and principal log strains."""
  e = rng.uniform(log_mean[0], log_mean[1], (n, 1)) + rng.uniform(
      -log_spread, log_spread, (n, 2))
  ra = _rotation(rng.uniform(-np.pi, np.pi, n))
  rb = _rotation(rng.uniform(-np.pi, np.pi, n))
  return ra @ (np.exp(e)[..., :, None] * rb)


def _principal(tau):
  """Principal values (ascending) of symmetric 2x2 stresses, numpy float64."""
  return np.linalg.eigvalsh(np.asarray(tau, np.float64))


class LameTest(absltest.TestCase):

  def test_inverts_to_youngs_modulus_and_poisson_ratio(self):
    mu, lam = constitutive.lame_parameters(E, NU)
    np.testing.assert_allclose(mu * (3 * lam + 2 * mu) / (lam + mu), E,
                               rtol=1e-12, atol=0)
    np.testing.assert_allclose(lam / (2 * (lam + mu)), NU, rtol=1e-12, atol=0)


class LogStrainTest(absltest.TestCase):

  def test_matches_eigendecomposition(self):
    rng = np.random.default_rng(0)
    f = _random_f(rng, 500, log_spread=0.3)
    trace, dev = _log_strain(jnp.asarray(f, jnp.float32))
    b = f @ np.swapaxes(f, -1, -2)
    w, v = np.linalg.eigh(b)
    eps = 0.5 * np.einsum("nij,nj,nkj->nik", v, np.log(w), v)
    np.testing.assert_allclose(trace, np.trace(eps, axis1=1, axis2=2),
                               atol=1e-5, rtol=0)
    np.testing.assert_allclose(dev[:, 0], (eps[:, 0, 0] - eps[:, 1, 1]) / 2,
                               atol=1e-5, rtol=0)
    np.testing.assert_allclose(dev[:, 1], eps[:, 0, 1], atol=1e-5, rtol=0)


class KirchhoffStressTest(parameterized.TestCase):

  def test_zero_at_identity(self):
    tau = constitutive.kirchhoff_stress(jnp.eye(2)[None], MU, LAM)
    np.testing.assert_allclose(tau, 0.0, atol=1e-6, rtol=0)

  def test_zero_for_rigid_rotations(self):
    f = _rotation(np.linspace(-3, 3, 7)).astype(np.float32)
    tau = _stress(jnp.asarray(f), MU, LAM)
    # Pa; float32 log of 1 +- ulp times a 1e5 modulus.
    np.testing.assert_allclose(tau, 0.0, atol=0.5, rtol=0)

  def test_symmetric(self):
    f = _random_f(np.random.default_rng(1), 200).astype(np.float32)
    tau = np.asarray(_stress(jnp.asarray(f), MU, LAM))
    np.testing.assert_allclose(tau, np.swapaxes(tau, -1, -2), atol=1e-3,
                               rtol=0)

  def test_objectivity(self):
    rng = np.random.default_rng(2)
    f = _random_f(rng, 200)
    r = _rotation(rng.uniform(-np.pi, np.pi, 200))
    with jax.enable_x64(True):
      tau = np.asarray(_stress(jnp.asarray(f), MU, LAM))
      tau_r = np.asarray(_stress(jnp.asarray(r @ f), MU,
                                                       LAM))
    expected = r @ tau @ np.swapaxes(r, -1, -2)
    # float64: relative to stresses of O(1e4) Pa.
    np.testing.assert_allclose(tau_r, expected, atol=1e-6, rtol=0)

  def test_is_the_gradient_of_the_hencky_energy(self):
    # psi = mu |eps|^2 + lam/2 tr(eps)^2 with eps = log(V); tau = dpsi/dF F^T.
    def energy(f):
      trace, dev = constitutive.log_strain(f)
      return MU * (trace**2 / 2 + 2 * jnp.sum(dev**2)) + LAM / 2 * trace**2

    f = _random_f(np.random.default_rng(3), 50, log_spread=0.2)
    with jax.enable_x64(True):
      grads = jax.jit(jax.vmap(jax.grad(energy)))(jnp.asarray(f))
      tau = np.asarray(_stress(jnp.asarray(f), MU, LAM))
    np.testing.assert_allclose(np.asarray(grads) @ np.swapaxes(f, -1, -2), tau,
                               atol=1e-6, rtol=1e-9)

  def test_linearises_to_hooke_at_identity(self):
    h = np.array([[0.3, -0.2], [0.5, 0.1]])
    _, dtau = jax.jvp(lambda f: constitutive.kirchhoff_stress(f, MU, LAM),
                      (jnp.eye(2),), (jnp.asarray(h, jnp.float32),))
    sym = (h + h.T) / 2
    expected = 2 * MU * sym + LAM * np.trace(h) * np.eye(2)
    self.assertTrue(np.all(np.isfinite(dtau)))
    np.testing.assert_allclose(dtau, expected, rtol=1e-5, atol=1e-2)


class ProjectTest(parameterized.TestCase):

  @parameterized.parameters(20.0, 35.0, 50.0)
  def test_matches_principal_form(self, phi_deg):
    rng = np.random.default_rng(int(phi_deg))
    n = 2000
    f = _random_f(rng, n)
    vc = np.where(rng.uniform(size=n) < 0.5, 0.0, rng.uniform(0, 0.05, n))
    alpha = constitutive.friction_coefficient(math.radians(phi_deg))
    with jax.enable_x64(True):
      args = (jnp.asarray(f), jnp.asarray(vc), MU, LAM, alpha)
      f_t, vc_t = map(np.asarray, _project(*args))
      f_p, vc_p = map(np.asarray, _project_principal(*args))
      trace, dev = map(np.asarray, _log_strain(jnp.asarray(f)))
    # The sample covers all three branches of the return mapping.
    trace_c = trace + vc
    dev_norm = np.sqrt(2 * np.sum(dev**2, -1))
    on_cone = (trace_c < 0) & (dev_norm + (LAM + MU) / MU * alpha * trace_c > 0)
    self.assertGreater(np.sum(trace_c >= 0), n // 10)
    self.assertGreater(np.sum(on_cone), n // 10)
    self.assertGreater(np.sum(~on_cone & (trace_c < 0)), n // 10)
    # float64 on both sides; the SVD form differs only by rounding.
    np.testing.assert_allclose(f_t, f_p, atol=1e-9, rtol=0)
    np.testing.assert_allclose(vc_t, vc_p, atol=1e-12, rtol=0)

  @parameterized.parameters(20.0, 35.0, 50.0)
  def test_returns_to_mohr_coulomb_cone(self, phi_deg):
    rng = np.random.default_rng(10 + int(phi_deg))
    n = 1000
    # Compressed (trace < 0) with large shear: the trial state is outside.
    f = _random_f(rng, n, log_mean=(-0.05, -0.02), log_spread=0.0)
    shear = _rotation(rng.uniform(-np.pi, np.pi, n))
    g = rng.uniform(0.1, 0.3, n)
    f = shear @ (np.exp(np.stack([g, -g], -1))[..., :, None] *
                 np.swapaxes(shear, -1, -2)) @ f
    phi = math.radians(phi_deg)
    with jax.enable_x64(True):
      alpha = constitutive.friction_coefficient(phi)
      tau_trial = _stress(jnp.asarray(f), MU, LAM)
      f_new, vc = _project(jnp.asarray(f), jnp.zeros(n), MU, LAM,
                                       alpha)
      tau = _stress(f_new, MU, LAM)
    s_trial = _principal(tau_trial)
    s = _principal(tau)
    # The trial states violate |s1 - s2| <= -(s1 + s2) sin(phi) ...
    self.assertTrue(np.all(s_trial[:, 1] - s_trial[:, 0] >
                           -(s_trial[:, 0] + s_trial[:, 1]) * math.sin(phi)))
    # ... and the projected ones meet it with equality, at the same pressure.
    np.testing.assert_allclose(s[:, 1] - s[:, 0],
                               -(s[:, 0] + s[:, 1]) * math.sin(phi),
                               rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(s.sum(-1), s_trial.sum(-1), rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(vc, 0.0, atol=0, rtol=0)

  def test_elastic_inside_cone(self):
    # Pure compression with a little shear: inside the cone, F unchanged.
    f = np.diag([np.exp(-0.02 + 0.001), np.exp(-0.02 - 0.001)])[None]
    alpha = constitutive.friction_coefficient(math.radians(35.0))
    with jax.enable_x64(True):
      f_new, vc = _project(jnp.asarray(f), jnp.zeros(1), MU, LAM,
                                       alpha)
    np.testing.assert_allclose(f_new, f, atol=1e-12, rtol=0)
    np.testing.assert_allclose(vc, 0.0, atol=0, rtol=0)

  def test_expansion_is_stress_free_and_stores_volume(self):
    rng = np.random.default_rng(4)
    n = 100
    f = _random_f(rng, n, log_mean=(0.01, 0.05), log_spread=0.005)
    vc0 = rng.uniform(0, 0.02, n)
    alpha = constitutive.friction_coefficient(math.radians(35.0))
    with jax.enable_x64(True):
      f_new, vc = _project(jnp.asarray(f), jnp.asarray(vc0), MU,
                                       LAM, alpha)
      tau = np.asarray(_stress(f_new, MU, LAM))
    f_new = np.asarray(f_new)
    # F becomes the rotation of its polar decomposition.
    np.testing.assert_allclose(np.swapaxes(f_new, -1, -2) @ f_new,
                               np.broadcast_to(np.eye(2), (n, 2, 2)),
                               atol=1e-12, rtol=0)
    np.testing.assert_allclose(np.linalg.det(f_new), 1.0, atol=1e-12, rtol=0)
    u, _, vt = np.linalg.svd(f)
    np.testing.assert_allclose(f_new, u @ vt, atol=1e-12, rtol=0)
    np.testing.assert_allclose(tau, 0.0, atol=1e-6, rtol=0)
    # The extra volume is remembered: v_c += log det F.
    np.testing.assert_allclose(vc, vc0 + np.log(np.linalg.det(f)), atol=1e-12,
                               rtol=0)

  def test_compression_first_takes_up_stored_volume(self):
    # 1% compression against 2% of stored separation: still stress free.
    f = np.exp(-0.005) * np.eye(2)[None]
    alpha = constitutive.friction_coefficient(math.radians(35.0))
    with jax.enable_x64(True):
      f_new, vc = _project(jnp.asarray(f), jnp.asarray([0.02]),
                                       MU, LAM, alpha)
    np.testing.assert_allclose(f_new, np.eye(2)[None], atol=1e-12, rtol=0)
    np.testing.assert_allclose(vc, [0.01], atol=1e-12, rtol=0)

  def test_gradients_finite_at_identity(self):
    alpha = constitutive.friction_coefficient(math.radians(35.0))

    def loss(f, vc):
      f_new, vc_new = _project(f, vc, MU, LAM, alpha)
      tau = _stress(f_new, MU, LAM)
      return jnp.sum(tau**2) + jnp.sum(f_new * f_new) + jnp.sum(vc_new)

    f = jnp.broadcast_to(jnp.eye(2), (3, 2, 2))
    g_f, g_vc = jax.jit(jax.grad(loss, argnums=(0, 1)))(f, jnp.zeros(3))
    self.assertTrue(np.all(np.isfinite(g_f)))
    self.assertTrue(np.all(np.isfinite(g_vc)))
    # At F = I the expansion branch is taken (F -> R, v_c -> log det F):
    # d(sum R.R)/dF = 0 and d(v_c)/dF = I.
    np.testing.assert_allclose(g_f, np.broadcast_to(np.eye(2), (3, 2, 2)),
                               atol=1e-5, rtol=0)

    g_tau = jax.jacfwd(lambda f: constitutive.kirchhoff_stress(f, MU, LAM))(
        jnp.eye(2))
    self.assertTrue(np.all(np.isfinite(g_tau)))

  def test_gradient_finite_on_cone_and_inside(self):
    alpha = constitutive.friction_coefficient(math.radians(35.0))
    f = _random_f(np.random.default_rng(5), 200,
                  log_mean=(-0.05, -0.01)).astype(np.float32)

    def loss(f):
      f_new, _ = _project(f, jnp.zeros(f.shape[0]), MU, LAM, alpha)
      return jnp.sum(_stress(f_new, MU, LAM))

    grad = jax.jit(jax.grad(loss))(jnp.asarray(f))
    self.assertTrue(np.all(np.isfinite(grad)))
    self.assertGreater(np.max(np.abs(grad)), 0.0)



def _mu_i(mu_s=0.6, mu_2=0.86, i_0=0.279, d=5e-4, rho_s=2650.0):
  return constitutive.MuI(*(jnp.float32(v) for v in (mu_s, mu_2, i_0, d,
                                                     rho_s)))


_project_mu_i = jax.jit(constitutive.project_mu_i)


def _pressure_and_shear(tau):
  """p = -tr(tau) / 2 and tau_eq = ||dev tau||_F / sqrt(2), float64."""
  tau = np.asarray(tau, np.float64)
  p = -(tau[..., 0, 0] + tau[..., 1, 1]) / 2
  dev = tau + p[..., None, None] * np.eye(2)
  return p, np.sqrt((dev**2).sum((-2, -1)) / 2)


def _steady_shear(rheology, shear_rate, steps, dt=1e-5):
  """A material point sheared at a constant rate (1/s) under a constant
  pressure (simple shear keeps the volume) for ``steps`` steps: its
  tau_eq / p and I = shear_rate d / sqrt(p / rho_s) at the end."""
  step = jnp.asarray([[1.0, shear_rate * dt], [0.0, 1.0]], jnp.float32)
  f0 = jnp.eye(2, dtype=jnp.float32) * math.exp(-0.0005)

  def body(_, state):
    f, vc = state
    return _project_mu_i(step @ f, vc, MU, LAM, rheology, dt)

  f, _ = jax.jit(lambda f0: jax.lax.fori_loop(
      0, steps, body, (f0, jnp.zeros(()))))(f0)
  p, tau = _pressure_and_shear(constitutive.kirchhoff_stress(f, MU, LAM))
  return tau / p, shear_rate * 5e-4 / math.sqrt(p / 2650.0)


class MuITest(parameterized.TestCase):
  """The mu(I) return map (``project_mu_i``)."""

  def test_with_mu_2_equal_to_mu_s_it_is_drucker_prager(self):
    phi = math.radians(35.0)
    f = _random_f(np.random.default_rng(3), 500).astype(np.float32)
    vc = np.zeros(500, np.float32)
    f_dp, vc_dp = _project(f, vc, MU, LAM,
                           constitutive.friction_coefficient(phi))
    f_mi, vc_mi = _project_mu_i(f, vc, MU, LAM,
                                _mu_i(math.sin(phi), math.sin(phi)), 1e-4)
    np.testing.assert_allclose(f_mi, f_dp, rtol=0, atol=2e-6)
    np.testing.assert_array_equal(vc_mi, vc_dp)

  def test_a_hand_computed_return(self):
    # Compressed by 0.1% in area and sheared by 0.4%: p = 340 Pa, the
    # trial's tau_eq = 544 Pa, far above mu_s p = 204 Pa.
    f = np.array([[1.0, 0.004], [0.0, 1.0]]) * math.exp(-0.0005)
    dt, rheology = 1e-4, _mu_i()
    p_tr, tau_tr = _pressure_and_shear(constitutive.kirchhoff_stress(
        jnp.asarray(f, jnp.float32), MU, LAM))
    # By hand, in float64: y = tau_tr - tau solves
    # (S - y)(I_0 + c y) = (mu_2 - mu_s) p c y, S = tau_tr - mu_s p.
    p = -(MU + LAM) * math.log(np.linalg.det(f))
    c = 5e-4 / (MU * dt * math.sqrt(p / 2650.0))
    excess = tau_tr - 0.6 * p
    y = max(np.roots([c, 0.279 + c * (0.26 * p - excess),
                      -excess * 0.279]))
    f_new, _ = _project_mu_i(jnp.asarray(f, jnp.float32), jnp.zeros(()),
                             MU, LAM, rheology, dt)
    p_new, tau_new = _pressure_and_shear(
        constitutive.kirchhoff_stress(f_new, MU, LAM))
    self.assertAlmostEqual(p_new / p, 1.0, delta=1e-3)   # deviatoric only
    self.assertAlmostEqual(tau_new / (tau_tr - y), 1.0, delta=2e-3)
    # ... and the state it returns to is on mu(I) at the rate it implies.
    inertial = (tau_tr - tau_new) / (MU * dt) * 5e-4 / math.sqrt(
        p / 2650.0)
    mu_expected = float(constitutive.mu_of_i(inertial, rheology))
    self.assertAlmostEqual(tau_new / p_new, mu_expected, delta=2e-3)
    self.assertBetween(tau_new / p_new, 0.6, 0.86)

  def test_inside_mu_s_nothing_changes(self):
    f = _random_f(np.random.default_rng(4), 300, log_mean=(-0.05, -0.03),
                  log_spread=1e-4).astype(np.float32)
    p, tau = _pressure_and_shear(constitutive.kirchhoff_stress(f, MU, LAM))
    self.assertTrue(np.all(tau < 0.6 * p))
    f_new, vc = _project_mu_i(f, np.zeros(300, np.float32), MU, LAM,
                              _mu_i(), 1e-4)
    np.testing.assert_array_equal(f_new, f)
    np.testing.assert_array_equal(vc, 0.0)

  @parameterized.parameters(30.0, 200.0, 1000.0)
  def test_steady_simple_shear_follows_mu_of_i(self, shear_rate):
    """A material point sheared at a constant rate under a constant
    pressure (simple shear keeps the volume) reaches tau_eq = mu(I) p with
    I = shear_rate d / sqrt(p / rho_s): the local law behind the
    Bagnold profile."""
    rheology = _mu_i()
    ratio, inertial = _steady_shear(rheology, shear_rate, 3000)
    expected = float(constitutive.mu_of_i(inertial, rheology))
    self.assertAlmostEqual(ratio, expected, delta=0.01 * expected)

  def test_gradients_finite_at_identity_on_and_inside(self):
    f = np.concatenate([
        np.broadcast_to(np.eye(2), (3, 2, 2)),
        _random_f(np.random.default_rng(5), 200, log_mean=(-0.05, -0.01))
    ]).astype(np.float32)

    def loss(f, rheology):
      f_new, vc = constitutive.project_mu_i(f, jnp.zeros(f.shape[0]), MU,
                                            LAM, rheology, 1e-4)
      return jnp.sum(_stress(f_new, MU, LAM)) + jnp.sum(vc)

    g_f, g_r = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(f),
                                                       _mu_i())
    self.assertTrue(np.all(np.isfinite(g_f)))
    leaves = jax.tree.leaves(g_r)
    self.assertTrue(all(np.all(np.isfinite(x)) for x in leaves))
    self.assertGreater(abs(float(g_r.mu_s)), 0.0)


# Glass beads (Jop, Forterre & Pouliquen 2006): mu(I) is well-posed from
# I_N = 0.0197 up, so the partial regularisation applies.
GLASS = (0.383, 0.643, 0.279)


def _regularized(alpha=1.9):
  i_n = constitutive.regularization_threshold(*GLASS)
  return constitutive.MuI(*(jnp.float32(v) for v in GLASS + (5e-4, 2650.0)),
                          I_N=jnp.float32(i_n), alpha_reg=jnp.float32(alpha))


def _mu_regularized_64(inertial, alpha=1.9):
  """Barker & Gray's law in float64, written out here."""
  mu_s, mu_2, i_0 = GLASS
  i_n = constitutive.regularization_threshold(*GLASS)
  mu_n = mu_s + (mu_2 - mu_s) * i_n / (i_0 + i_n)
  log_a = math.log(i_n) + alpha / mu_n**2
  inertial = np.maximum(inertial, 1e-300)
  return np.where(inertial >= i_n,
                  mu_s + (mu_2 - mu_s) * inertial / (i_0 + inertial),
                  np.sqrt(alpha / (log_a - np.log(inertial))))


class RegularizedMuITest(parameterized.TestCase):
  """Barker & Gray (2017)'s partial regularisation (``mu_i_regularized``)."""

  def test_threshold_is_where_the_plain_law_turns_well_posed(self):
    mu_s, mu_2, i_0 = GLASS
    i_n = constitutive.regularization_threshold(*GLASS)
    self.assertBetween(i_n, 0.015, 0.025)
    for i, ill in ((0.99 * i_n, True), (1.01 * i_n, False), (0.1, False)):
      mu = mu_s + (mu_2 - mu_s) * i / (i_0 + i)
      c = constitutive.ill_posedness(i, mu, (mu_2 - mu_s) * i_0 / (i_0 + i)**2)
      self.assertEqual(c > 0, ill, msg=f"I = {i:g}: C = {c:g}")
    # Constant friction (nu = 0) is ill-posed; so is the paper's sand.
    self.assertGreater(constitutive.ill_posedness(0.1, 0.6, 0.0), 0)
    sand = math.sin(math.radians(35.0))
    self.assertIsNone(
        constitutive.regularization_threshold(sand, sand + 0.26, 0.279))

  def test_the_law_is_continuous_well_posed_below_i_n_and_tends_to_zero(self):
    rheology = _regularized()
    i_n = float(rheology.I_N)
    above = float(constitutive.mu_regularized(i_n * 1.0001, rheology))
    below = float(constitutive.mu_regularized(i_n * 0.9999, rheology))
    self.assertAlmostEqual(above, below, delta=1e-4)
    i = np.logspace(-30, math.log10(i_n), 300)
    mu = np.asarray(constitutive.mu_regularized(jnp.asarray(i), rheology))
    np.testing.assert_allclose(mu, _mu_regularized_64(i), rtol=1e-5)
    # Below I_N: nu = I mu' / mu = mu^2 / (2 alpha).
    self.assertTrue(np.all(constitutive.ill_posedness(
        1.0, mu, mu**3 / (2 * 1.9)) <= 0))
    self.assertLess(mu[0], 0.2)    # no yield stress: mu -> 0 as I -> 0

  def test_the_return_against_a_brute_force_root(self):
    """Trial states from far below mu_s (creep at I ~ 1e-30) to far above
    (I > I_N): the returned shear stress is tau_trial - y with y the root,
    by bisection in float64, of tau_trial - y = p mu(c y)."""
    rng = np.random.default_rng(7)
    n, dt = 400, 1e-4
    # Compressed by 0.02-2% in area, sheared so that tau_trial / p is
    # 0.1-1.2.
    log_j = -rng.uniform(2e-4, 2e-2, n)
    p = -(MU + LAM) * log_j
    ratio = rng.uniform(0.1, 1.2, n)
    shear = ratio * p / (2 * MU)     # tau_eq = 2 mu eps_xy for small shear
    f = np.zeros((n, 2, 2))
    f[:, 0, 0] = f[:, 1, 1] = np.exp(log_j / 2)
    f[:, 0, 1] = f[:, 1, 0] = np.sinh(shear) * np.exp(log_j / 2)
    f = f.astype(np.float32)
    p_tr, tau_tr = _pressure_and_shear(constitutive.kirchhoff_stress(
        f, MU, LAM))
    c = 5e-4 / (MU * dt * np.sqrt(p_tr / 2650.0))
    lo, hi = np.zeros(n), tau_tr.copy()
    for _ in range(200):
      mid = (lo + hi) / 2
      up = tau_tr - mid - p_tr * _mu_regularized_64(c * mid) > 0
      lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    f_new, _ = _project_mu_i(f, np.zeros(n, np.float32), MU, LAM,
                             _regularized(), dt)
    _, tau_new = _pressure_and_shear(constitutive.kirchhoff_stress(
        f_new, MU, LAM))
    np.testing.assert_allclose(tau_new, tau_tr - lo, rtol=0,
                               atol=2e-4 * tau_tr.max())
    implied = c * lo
    i_n = constitutive.regularization_threshold(*GLASS)
    self.assertGreater(np.sum(implied > i_n), 20)      # both branches
    self.assertGreater(np.sum(implied < 1e-6), 20)     # creep, below mu_s

  def test_above_i_n_it_is_the_plain_return(self):
    f = _random_f(np.random.default_rng(8), 500).astype(np.float32)
    plain = constitutive.MuI(*(jnp.float32(v) for v in GLASS + (5e-4,
                                                                 2650.0)))
    dt = 1e-4
    f_plain, vc_plain = _project_mu_i(f, np.zeros(500, np.float32), MU, LAM,
                                      plain, dt)
    f_reg, vc_reg = _project_mu_i(f, np.zeros(500, np.float32), MU, LAM,
                                  _regularized(), dt)
    p, tau_tr = _pressure_and_shear(constitutive.kirchhoff_stress(f, MU, LAM))
    _, tau_plain = _pressure_and_shear(constitutive.kirchhoff_stress(
        f_plain, MU, LAM))
    implied = (tau_tr - tau_plain) / (MU * dt) * 5e-4 / np.sqrt(
        np.maximum(p, 1e-9) / 2650.0)
    fast = (p > 0) & (implied > 1.05 * constitutive.regularization_threshold(
        *GLASS))
    self.assertGreater(fast.sum(), 50)
    np.testing.assert_array_equal(f_reg[fast], f_plain[fast])
    np.testing.assert_array_equal(vc_reg, vc_plain)

  @parameterized.parameters(3.0, 10.0)
  def test_steady_simple_shear_below_i_n_follows_the_regularized_law(
      self, shear_rate):
    rheology = _regularized()
    ratio, inertial = _steady_shear(rheology, shear_rate, 4000)
    self.assertLess(inertial, float(rheology.I_N))
    expected = float(_mu_regularized_64(inertial))
    self.assertAlmostEqual(ratio, expected, delta=0.01 * expected)

  def test_gradients_finite_and_match_finite_differences(self):
    f = np.concatenate([
        np.broadcast_to(np.eye(2), (3, 2, 2)),
        _random_f(np.random.default_rng(9), 200, log_mean=(-0.05, -0.01))
    ]).astype(np.float32)

    def loss(f, alpha):
      rheology = _regularized().replace(alpha_reg=alpha)
      f_new, vc = constitutive.project_mu_i(f, jnp.zeros(f.shape[0]), MU,
                                            LAM, rheology, 1e-4)
      return jnp.sum(_stress(f_new, MU, LAM)) + jnp.sum(vc)

    g_f, g_alpha = jax.jit(jax.grad(loss, argnums=(0, 1)))(
        jnp.asarray(f), jnp.float32(1.9))
    self.assertTrue(np.all(np.isfinite(g_f)))
    # A wide step: the stresses' float32 rounding swamps a narrow one.
    h = 0.1
    fd = (loss(f, jnp.float32(1.9 + h)) - loss(f, jnp.float32(1.9 - h))) / (
        2 * h)
    self.assertNotEqual(float(g_alpha), 0.0)
    self.assertAlmostEqual(float(g_alpha) / float(fd), 1.0, delta=0.02)


def _compressible(dilatancy=4.09, phi_max=0.6, phi_min=0.4):
  return _mu_i().replace(phi_max=jnp.float32(phi_max),
                         phi_min=jnp.float32(phi_min),
                         dilatancy=jnp.float32(dilatancy))


_advect = jax.jit(constitutive.advect_volume_fraction)


def _steady_shear_compressible(rheology, phi0, shear_rate, dt=1e-5,
                               strain=8.0):
  """A material point sheared at a constant rate (1/s) to a shear strain
  ``strain``, its pressure held at p0 = (mu + lam) 0.001 = 340 Pa by a
  servo (each step an isotropic stretch brings its elastic log volume back
  to -0.001): free to dilate or compact. Its tau_eq / p, I, phi at the end,
  and phi J, J the total volume ratio (the grains' volume, phi0)."""
  steps = int(round(strain / (shear_rate * dt)))
  f0 = jnp.eye(2, dtype=jnp.float32) * math.exp(-0.0005)

  def body(_, state):
    f, vc, phi, log_j = state
    trace, _ = constitutive.log_strain(f)
    rate = (-0.001 - trace) / (2 * dt)
    grad = jnp.stack([jnp.stack([rate, jnp.float32(shear_rate)]),
                      jnp.stack([jnp.float32(0), rate])])
    phi = constitutive.advect_volume_fraction(phi, grad, dt)
    step = jnp.eye(2) + dt * grad
    f, vc = constitutive.project_mu_i(step @ f, vc, MU, LAM, rheology, dt,
                                      phi)
    return f, vc, phi, log_j + jnp.log(jnp.linalg.det(step))

  f, _, phi, log_j = jax.jit(lambda f0: jax.lax.fori_loop(
      0, steps, body, (f0, jnp.zeros(()), jnp.float32(phi0),
                       jnp.zeros(()))))(f0)
  p, tau = _pressure_and_shear(constitutive.kirchhoff_stress(f, MU, LAM))
  return (tau / p, shear_rate * 5e-4 / math.sqrt(p / 2650.0), float(phi),
          float(phi) * math.exp(float(log_j)))


class CompressibleMuITest(parameterized.TestCase):
  """The compressible mu(I) (``mu_i_compressible``): a volume fraction phi
  relaxing toward phi_eq(I) through the dilatancy tan psi = K (phi -
  phi_eq(I))."""

  def test_without_dilatancy_it_is_the_plain_return(self):
    """K = 0 makes the same float32 operations give the same values: bit
    for bit op by op; compiled, XLA fuses the two programs differently
    (and may contract a multiply-add), within 2 ulps."""
    f = _random_f(np.random.default_rng(11), 500).astype(np.float32)
    vc = np.random.default_rng(12).uniform(0, 0.01, 500).astype(np.float32)
    vc[::2] = 0.0
    phi = np.random.default_rng(13).uniform(0.4, 0.7, 500).astype(
        np.float32)
    for project in (constitutive.project_mu_i, _project_mu_i):
      f_plain, vc_plain = project(f, vc, MU, LAM, _mu_i(), 1e-4)
      f_k0, vc_k0 = project(f, vc, MU, LAM, _compressible(0.0), 1e-4, phi)
      if project is _project_mu_i:
        np.testing.assert_array_max_ulp(f_k0, f_plain, maxulp=2)
      else:
        np.testing.assert_array_equal(f_k0, f_plain)
      np.testing.assert_array_equal(vc_k0, vc_plain)
    # ... and with it, the flow differs.
    f_k, _ = _project_mu_i(f, vc, MU, LAM, _compressible(), 1e-4, phi)
    self.assertGreater(np.abs(f_k - f_plain).max(), 1e-5)

  @parameterized.parameters((0.62, 1), (0.56, -1), (0.5, 0))
  def test_a_hand_computed_return(self, phi, sign):
    # As MuITest's: p = 340 Pa, tau_eq = 544 Pa; a dense sample (phi above
    # phi_eq of the return's I) dilates, a loose one compacts (sign: of the
    # pressure's change; 0: so loose that compacting by tan psi y / mu
    # would pass zero pressure, which is where it stops).
    f = np.array([[1.0, 0.004], [0.0, 1.0]]) * math.exp(-0.0005)
    dt, k = 1e-4, 4.09
    p_tr, tau_tr = _pressure_and_shear(constitutive.kirchhoff_stress(
        jnp.asarray(f, jnp.float32), MU, LAM))
    # By hand, in float64: (S - y)(I_0 + c y) = p c y ((mu_2 - mu_s) +
    # slope (I_0 + c y)), S = tau_tr - mu_rest p.
    p = -(MU + LAM) * math.log(np.linalg.det(f))
    c = 5e-4 / (MU * dt * math.sqrt(p / 2650.0))
    mu_rest, slope = 0.6 + k * (phi - 0.6), k * 0.2
    excess = tau_tr - mu_rest * p
    y = max(np.roots([c * (1 + slope * c * p),
                      0.279 + c * (0.26 * p - excess) + slope * c * p * 0.279,
                      -excess * 0.279]).real)
    inertial = c * y
    tan_psi = k * (phi - (0.6 - 0.2 * inertial))
    f_new, _ = _project_mu_i(jnp.asarray(f, jnp.float32), jnp.zeros(()),
                             MU, LAM, _compressible(k), dt, jnp.float32(phi))
    p_new, tau_new = _pressure_and_shear(
        constitutive.kirchhoff_stress(f_new, MU, LAM))
    self.assertAlmostEqual(tau_new / (tau_tr - y), 1.0, delta=2e-3)
    # The friction it returns to is mu(I) + tan psi at the trial pressure.
    self.assertAlmostEqual(
        (tau_tr - y) / p,
        float(constitutive.mu_of_i(inertial, _mu_i())) + tan_psi, delta=1e-6)
    # The plastic volume change tan psi y / mu is taken from the elastic
    # volume: the pressure rises by (mu + lam) of it.
    if sign:
      self.assertAlmostEqual((p_new - p) / ((MU + LAM) * tan_psi * y / MU),
                             1.0, delta=0.02)
      self.assertEqual(np.sign(p_new - p), sign)
    else:
      self.assertLess((MU + LAM) * tan_psi * y / MU, -p)
      self.assertLess(abs(p_new), 1e-3 * p)

  @parameterized.product(phi0=(0.62, 0.48), shear_rate=(30.0, 200.0))
  def test_steady_shear_relaxes_to_phi_eq_and_mu_of_i(self, phi0,
                                                     shear_rate):
    """Sheared at constant rate and pressure, a dense sample dilates and a
    loose one compacts to phi_eq(I) = 0.6 - 0.2 I of the imposed I, and
    the friction settles at mu(I); the grains' volume is kept."""
    rheology = _compressible()
    ratio, inertial, phi, grains = _steady_shear_compressible(
        rheology, phi0, shear_rate)
    expected_phi = 0.6 - 0.2 * inertial
    self.assertAlmostEqual(phi, expected_phi, delta=0.002)
    self.assertEqual(np.sign(phi - phi0), -1 if phi0 > expected_phi else 1)
    expected = float(constitutive.mu_of_i(inertial, rheology))
    self.assertAlmostEqual(ratio, expected, delta=0.01 * expected)
    self.assertAlmostEqual(grains / phi0, 1.0, delta=1e-4)

  def test_advection_keeps_the_grains_volume_and_a_physical_range(self):
    rng = np.random.default_rng(14)
    grad = rng.normal(0, 20, (200, 2, 2)).astype(np.float32)
    phi = rng.uniform(0.3, 0.65, 200).astype(np.float32)
    new = _advect(phi, grad, 1e-3)
    jac = np.linalg.det(np.eye(2) + 1e-3 * grad.astype(np.float64))
    np.testing.assert_allclose(new * jac, phi, rtol=1e-5)
    # Compressed past the grains' own volume, phi stops at 1.
    self.assertEqual(float(_advect(jnp.float32(0.9), -500 * jnp.eye(2),
                                   1e-3)), 1.0)

  def test_gradients_finite(self):
    f = np.concatenate([
        np.broadcast_to(np.eye(2), (3, 2, 2)),
        _random_f(np.random.default_rng(15), 200, log_mean=(-0.05, -0.01))
    ]).astype(np.float32)
    phi = np.random.default_rng(16).uniform(0.45, 0.65, 203).astype(
        np.float32)

    def loss(f, phi, rheology):
      f_new, vc = constitutive.project_mu_i(f, jnp.zeros(f.shape[0]), MU,
                                            LAM, rheology, 1e-4, phi)
      return jnp.sum(_stress(f_new, MU, LAM)) + jnp.sum(vc)

    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(
        jnp.asarray(f), jnp.asarray(phi), _compressible())
    leaves = jax.tree.leaves(grads)
    self.assertTrue(all(np.all(np.isfinite(x)) for x in leaves))
    self.assertGreater(abs(float(grads[2].dilatancy)), 0.0)
    self.assertGreater(np.abs(grads[1]).max(), 0.0)


if __name__ == "__main__":
  absltest.main()
