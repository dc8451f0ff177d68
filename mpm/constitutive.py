"""Dry sand: Hencky elasticity with a Drucker-Prager return mapping in 2D.

Follows Klar et al. (2016), "Drucker-Prager elastoplasticity for sand
animation", with the volume-correction term of Tampubolon et al. (2017). The
elastic deformation gradient F has the Hencky (logarithmic) strain

.. math:: \\epsilon = \\tfrac12 \\log(F F^T), \\qquad
   \\tau = 2 \\mu \\epsilon + \\lambda \\operatorname{tr}(\\epsilon) I,

where tau is the Kirchhoff stress. After each update of F the trial strain is
projected onto the cone ||dev tau|| <= -alpha tr(tau) (no cohesion):

* expansion (tr eps + v_c >= 0): the sand separates; F becomes its rotation
  (stress free) and v_c remembers the extra volume, which compression must
  take up before stress returns (the volume correction);
* inside the cone (delta_gamma <= 0): elastic, F unchanged;
* otherwise eps -> eps - delta_gamma dev(eps) / ||dev(eps)||.

Klar et al. write the projection on the singular values of F. Every step is
an isotropic function of the left stretch, so here it is written with the
tensors themselves: ``log_strain`` evaluates log(F F^T) in closed form and the
cone projection becomes F <- exp(-delta_gamma n) F with n the unit deviatoric
strain. The result is the same (``project_principal`` is the singular-value
form, kept as the reference the tests compare against) but smooth at
F = I, where every particle starts and where gradients through an SVD are
undefined.

All functions act per particle on leading batch dimensions. Units: Pa for
moduli and stress, radians for angles.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from mpm import _pytree
from mpm import linalg

_SQRT2 = 1.4142135623730951


def lame_parameters(youngs_modulus, poisson_ratio):
  """Lamé parameters (mu, lambda) [Pa] from E [Pa] and nu."""
  mu = youngs_modulus / (2 * (1 + poisson_ratio))
  lam = youngs_modulus * poisson_ratio / ((1 + poisson_ratio) *
                                          (1 - 2 * poisson_ratio))
  return mu, lam


def friction_coefficient(friction_angle):
  """Drucker-Prager alpha for a 2D (plane-strain) Mohr-Coulomb angle [rad].

  In 2D the Mohr-Coulomb condition on the principal stresses,
  |s1 - s2| <= -(s1 + s2) sin(phi), is exactly ||dev tau||_F <= -alpha tr(tau)
  with alpha = sin(phi) / sqrt(2). (Klar et al.'s sqrt(2/3) 2 sin(phi) /
  (3 - sin(phi)) fits the 3D cone instead; at 35 degrees the two differ by 5%.)
  """
  return jnp.sin(friction_angle) / _SQRT2


def _atanh_ratio(z2):
  """atanh(z) / z as a smooth function of z^2 in [0, 1)."""
  small = z2 < 1e-2
  series = 1 + z2 * (1 / 3 + z2 * (1 / 5 + z2 * (1 / 7 + z2 / 9)))
  # A safe value inside (0, 1): at z = 1 the untaken branch's atanh and its
  # derivative are infinite, and the backward pass forms 0 * inf = NaN
  # (masked by the inner where, but checkify flags it and fusion may not).
  z = jnp.sqrt(jnp.where(small, 0.25, z2))
  return jnp.where(small, series, jnp.arctanh(z) / z)


def log_strain(F):
  """Hencky strain of deformation gradients F [..., 2, 2].

  For the symmetric b = F F^T with mean eigenvalue m and half-gap r,
  log(b) = log(det b) / 2 I + (atanh(r/m) / r) (b - m I), which needs only r^2.

  Returns:
    trace: [...] tr(eps) = log|det F| (volumetric log strain).
    dev: [..., 2] deviatoric strain (d0, d1), eps_dev = [[d0, d1], [d1, -d0]].
  """
  f00, f01, f10, f11 = F[..., 0, 0], F[..., 0, 1], F[..., 1, 0], F[..., 1, 1]
  b00 = f00 * f00 + f01 * f01
  b11 = f10 * f10 + f11 * f11
  b01 = f00 * f10 + f01 * f11
  m = (b00 + b11) / 2
  h = (b00 - b11) / 2
  det = jnp.maximum(jnp.abs(f00 * f11 - f01 * f10), 1e-6)
  z2 = jnp.clip((h * h + b01 * b01) / (m * m), 0.0, 1.0 - 1e-6)
  c = _atanh_ratio(z2) / (2 * m)
  return jnp.log(det), jnp.stack([c * h, c * b01], -1)


def kirchhoff_stress(F, mu, lam):
  """Kirchhoff stress tau [..., 2, 2] (Pa) of Hencky elasticity."""
  trace, dev = log_strain(F)
  p = (mu + lam) * trace  # 2 mu tr/2 + lam tr: the isotropic part in 2D
  s0, s1 = 2 * mu * dev[..., 0], 2 * mu * dev[..., 1]
  return jnp.stack([jnp.stack([p + s0, s1], -1),
                    jnp.stack([s1, p - s0], -1)], -2)


def _deviatoric_norm(dev):
  """||dev eps||_F of the deviatoric strain (d0, d1), 0 where it is 0
  (with a finite gradient there)."""
  dev_sq = dev[..., 0]**2 + dev[..., 1]**2
  dev_norm = _SQRT2 * jnp.sqrt(jnp.where(dev_sq > 0, dev_sq, 1.0))
  return jnp.where(dev_sq > 0, dev_norm, 0.0)


def _return_map(F, trace_c, dev, dev_norm, delta_gamma):
  """F after the return: its rotation where the sand separates
  (trace_c >= 0), F <- exp(-delta_gamma n) F where delta_gamma > 0 (n the
  unit deviatoric strain), else F; and the new volume correction."""
  expand = trace_c >= 0
  on_cone = jnp.logical_and(~expand, delta_gamma > 0)

  # Cone: F <- exp(-delta_gamma n) F; n has eigenvalues +-1/sqrt(2).
  a = jnp.where(on_cone, delta_gamma, 0.0) / _SQRT2
  k = -jnp.sinh(a) * _SQRT2 / jnp.where(dev_norm > 0, dev_norm, 1.0)
  e00 = jnp.cosh(a) + k * dev[..., 0]
  e11 = jnp.cosh(a) - k * dev[..., 0]
  e01 = k * dev[..., 1]
  cone = jnp.stack([
      jnp.stack([e00 * F[..., 0, 0] + e01 * F[..., 1, 0],
                 e00 * F[..., 0, 1] + e01 * F[..., 1, 1]], -1),
      jnp.stack([e01 * F[..., 0, 0] + e11 * F[..., 1, 0],
                 e01 * F[..., 0, 1] + e11 * F[..., 1, 1]], -1)], -2)

  # Expansion: F <- R, the rotation of the polar decomposition F = V R.
  c = F[..., 0, 0] + F[..., 1, 1]
  s = F[..., 1, 0] - F[..., 0, 1]
  norm = jnp.sqrt(jnp.maximum(c * c + s * s, 1e-30))
  c, s = c / norm, s / norm
  rotation = jnp.stack([jnp.stack([c, -s], -1), jnp.stack([s, c], -1)], -2)

  F_new = jnp.where(expand[..., None, None], rotation,
                    jnp.where(on_cone[..., None, None], cone, F))
  return F_new, jnp.where(expand, trace_c, 0.0)


def project(F, volume_correction, mu, lam, alpha):
  """Drucker-Prager return mapping with volume correction (tensor form).

  Args:
    F: [..., 2, 2] trial elastic deformation gradients.
    volume_correction: [...] v_c, accumulated log volume of separation.
    mu, lam: Lamé parameters [Pa]; alpha: see ``friction_coefficient``.

  Returns:
    (F, volume_correction) after projection, same shapes.
  """
  trace, dev = log_strain(F)
  trace_c = trace + volume_correction
  dev_norm = _deviatoric_norm(dev)
  delta_gamma = dev_norm + (lam + mu) / mu * alpha * trace_c
  return _return_map(F, trace_c, dev, dev_norm, delta_gamma)


@_pytree.pytree_dataclass
class MuI:
  """The mu(I) rheology's parameters (GDR MiDi 2004; Jop, Forterre &
  Pouliquen 2006), all traced.

  Attributes:
    mu_s: [] friction at rest (I -> 0): tau_eq / p.
    mu_2: [] friction as I -> infinity.
    I_0: [] inertial number at which mu is halfway.
    grain_diameter: [] d (m).
    grain_density: [] rho_s (kg/m^3).
    I_N, alpha_reg: [] the regularisation's threshold (the lower end of the
      range where the plain law is well-posed, ``regularization_threshold``)
      and exponent; None for the plain law (a change of program structure).
    phi_max, phi_min, dilatancy: [] the compressible law's dilatancy law
      phi_eq(I) = phi_max - (phi_max - phi_min) I (the volume fraction of
      steady flow) and its K of tan psi = K (phi - phi_eq(I)); None for the
      incompressible laws.
  """
  mu_s: jax.Array
  mu_2: jax.Array
  I_0: jax.Array  # pylint: disable=invalid-name
  grain_diameter: jax.Array
  grain_density: jax.Array
  # Barker & Gray (2017)'s partial regularisation, or None for the plain
  # law: below I_N, mu = sqrt(alpha_reg / ln(A / I)) (``mu_regularized``).
  I_N: jax.Array | None = None  # pylint: disable=invalid-name
  alpha_reg: jax.Array | None = None
  # The compressible law (``project_mu_i`` with a volume fraction), or None.
  phi_max: jax.Array | None = None
  phi_min: jax.Array | None = None
  dilatancy: jax.Array | None = None


def mu_of_i(inertial_number, rheology: MuI):
  """mu(I) = mu_s + (mu_2 - mu_s) I / (I_0 + I)."""
  return plain_mu(inertial_number, rheology.mu_s, rheology.mu_2,
                  rheology.I_0)


def plain_mu(inertial_number, mu_s, mu_2, i_0):
  """``mu_of_i`` of loose parameters (numpy or jax; host-side checks)."""
  return mu_s + (mu_2 - mu_s) * (inertial_number / (i_0 + inertial_number))


def advect_volume_fraction(phi, velocity_gradient, dt):
  """phi [N] after a substep of the velocity gradient [N, 2, 2] (1/s): the
  grains' volume is conserved, so phi / det(I + dt L), kept in [0, 1]."""
  g = velocity_gradient * dt
  jacobian = (1 + g[..., 0, 0]) * (1 + g[..., 1, 1]) - g[..., 0, 1] * g[
      ..., 1, 0]
  return jnp.clip(phi / jnp.maximum(jacobian, 1e-6), 0.0, 1.0)


def _regularization_log_a(rheology: MuI):
  """ln A of the regularised branch, A = I_N exp(alpha_reg / mu(I_N)^2), so
  that mu is continuous at I_N (Barker & Gray 2017, eq. 6.4)."""
  return (jnp.log(rheology.I_N) +
          rheology.alpha_reg / mu_of_i(rheology.I_N, rheology)**2)


def mu_regularized(inertial_number, rheology: MuI):
  """Barker & Gray (2017)'s partially regularised law: mu(I) for I >= I_N,
  sqrt(alpha_reg / ln(A / I)) below, which tends to 0 as I -> 0 (no yield
  stress: sand below mu_s creeps, at a rate exponentially small in
  1 / mu^2)."""
  i = jnp.maximum(inertial_number, 1e-30)
  low = jnp.sqrt(rheology.alpha_reg /
                 (_regularization_log_a(rheology) - jnp.log(i)))
  return jnp.where(i >= rheology.I_N, mu_of_i(i, rheology), low)


def ill_posedness(inertial_number, mu, dmu_di):
  """Barker & Gray (2017, eq. 3.9)'s C = 4 nu^2 - 4 nu + mu^2 (1 - nu/2)^2,
  nu = I mu'(I) / mu, of the incompressible mu(I) equations in 2D: they are
  ill-posed (short waves grow without bound, so a numerical answer depends on
  the grid) where C > 0. numpy or jax arrays."""
  nu = inertial_number * dmu_di / mu
  return 4 * nu**2 - 4 * nu + mu**2 * (1 - nu / 2)**2


def _plain_ill_posedness(i, mu_s, mu_2, i_0):
  return ill_posedness(i, plain_mu(i, mu_s, mu_2, i_0),
                       (mu_2 - mu_s) * i_0 / (i_0 + i)**2)


# Pure in its floats; each scene's setup asks again (dataset generation:
# once per trajectory).
@functools.lru_cache(maxsize=64)
def regularization_threshold(mu_s: float, mu_2: float,
                             i_0: float) -> float | None:
  """I_N: the lowest inertial number at which the plain mu(I) law is
  well-posed (``ill_posedness`` <= 0; float64, host side), or None where it
  is ill-posed at every I in [1e-9, 100] (for mu_2 - mu_s = 0.26 and
  I_0 = 0.279: every mu_s above 0.52, the paper's sand among them)."""
  grid = np.logspace(-9, 2, 2201)
  ok = np.flatnonzero(_plain_ill_posedness(grid, mu_s, mu_2, i_0) <= 0)
  if not ok.size:
    return None
  if ok[0] == 0:
    return float(grid[0])
  lo, hi = grid[ok[0] - 1], grid[ok[0]]
  for _ in range(60):
    mid = math.sqrt(lo * hi)
    if _plain_ill_posedness(mid, mu_s, mu_2, i_0) <= 0:
      hi = mid
    else:
      lo = mid
  return float(hi)


def _quadratic_drop(tau_trial, p, c, rheology: MuI, yielding, mu_s=None,
                    slope=None):
  """The plain law's return: the drop y = tau_trial - tau of a yielding
  state, the positive root of the quadratic of ``project_mu_i``.

  With ``mu_s`` [...] and ``slope`` [] given, the friction is
  mu_s + (mu_2 - mu_s) I / (I_0 + I) + slope I (the compressible law's,
  mu(I) + tan psi): the quadratic's leading coefficient becomes
  c (1 + slope c p) and its linear one gains slope c p I_0.
  """
  # Safe values where it does not yield keep both branches' gradients
  # finite.
  p = jnp.where(yielding, p, 1.0)
  c = jnp.where(yielding, c, 1.0)
  s = jnp.where(yielding, tau_trial - (rheology.mu_s if mu_s is None else
                                       mu_s) * p, 1.0)
  b = rheology.I_0 + c * ((rheology.mu_2 - rheology.mu_s) * p - s)
  a = c
  if slope is not None:
    a = c * (1 + slope * c * p)
    b = b + slope * c * p * rheology.I_0
  root = jnp.sqrt(b * b + 4 * a * s * rheology.I_0)
  # The positive root, each form free of cancellation on its side.
  return jnp.where(b >= 0, 2 * s * rheology.I_0 / (b + root),
                   (root - b) / (2 * a))


# Newton steps of the regularised return: monotone from below (see
# ``_regularized_drop``); 8 reach float32's precision over I from 1e-30 to
# I_N (7: 3e-5 of tau_trial; tests/mpm/constitutive_test.py); one more
# carries the gradient.
_REGULARIZED_NEWTON_STEPS = 8
# w = ln(A / I) beyond which the plastic rate is negligible (I < A e^-80).
_W_MAX = 80.0


def _regularized_drop(tau_trial, p, c, rheology: MuI, low):
  """The regularised branch's return (I < I_N): the drop y with
  tau_trial - y = p sqrt(alpha / w), w = ln(A / I), I = c y.

  In w the condition reads r(w) = T - (A / (c p)) e^-w - sqrt(alpha / w)
  = 0 with T = tau_trial / p: r increases and is concave, so Newton from
  w0 = max(w_N, alpha / T^2) <= w* climbs to the root without overshooting.
  The iterations carry no gradient; one last step with live parameters
  carries the implicit function's.
  """
  p = jnp.where(low, p, 1.0)
  c = jnp.where(low, c, 1.0)
  # Elsewhere a ratio inside the branch (below mu(I_N)) keeps the unused
  # iterations finite, and so the gradients of the used ones.
  ratio = jnp.where(low, tau_trial / p,
                    0.5 * mu_of_i(rheology.I_N, rheology))
  alpha = rheology.alpha_reg
  log_a = _regularization_log_a(rheology)
  log_scale = log_a - jnp.log(c * p)          # ln(A / (c p))
  w_n = log_a - jnp.log(rheology.I_N)

  def residual(w, ratio, log_scale, alpha):
    """r(w) and r'(w)."""
    fall, mu_w = jnp.exp(log_scale - w), jnp.sqrt(alpha / w)
    return ratio - fall - mu_w, fall + 0.5 * mu_w / w

  stopped = jax.lax.stop_gradient((ratio, log_scale, alpha))
  w_n = jax.lax.stop_gradient(w_n)
  w = jnp.minimum(jnp.maximum(stopped[2] / stopped[0]**2, w_n), _W_MAX)
  for _ in range(_REGULARIZED_NEWTON_STEPS):
    r, dr = residual(w, *stopped)
    # The root lies at w >= w_N (I <= I_N); rounding may not step past it.
    w = jnp.maximum(w - r / dr, w_n)
  w = jax.lax.stop_gradient(w)
  r, dr = residual(w, ratio, log_scale, alpha)
  w = w - r / dr
  return jnp.exp(log_a - w) / c


def project_mu_i(F, volume_correction, mu, lam, rheology: MuI, dt,
                 volume_fraction=None):
  """The mu(I) return mapping: explicit, one quadratic per yielding
  particle (as Dunatunga & Kamrin 2015; ``PlasticModel::DPMui`` of the MPM
  code larsblatny/matter).

  With p = -(mu + lam) tr(eps) the pressure and tau_eq = sqrt(2) mu
  ||dev eps||_F the equivalent shear stress (tau_eq = ||dev tau||_F /
  sqrt(2)), a trial state with tau_eq > mu_s p returns to
  tau = mu(I) p, where I = gamma_p d / sqrt(p / rho_s) and gamma_p =
  (tau_trial - tau) / (mu dt) is the plastic shear rate the return
  implies. With y = tau_trial - tau and S = tau_trial - mu_s p:

    c y^2 + (I_0 + c (mu_2 - mu_s) p - c S) y - S I_0 = 0,
    c = d / (mu dt sqrt(p / rho_s)),

  whose positive root is taken. With mu_2 = mu_s it is y = S: the
  Drucker-Prager return at alpha = mu_s / sqrt(2) (``project``).
  Separation (tr eps + v_c >= 0) is handled as there.

  With the regularisation (``rheology.I_N`` set) every compressed state
  with shear yields: where the return lands at I >= I_N it is the
  quadratic's, below it ``_regularized_drop``'s (a few Newton steps).

  The compressible law (``rheology.dilatancy`` set; after Heyman et al.
  2017, with the dilatancy of Roux & Radjai 1998 and Pailha & Pouliquen
  2009) takes the volume fraction phi: the friction is mu(I) + tan psi,
  tan psi = K (phi - phi_eq(I)), still one quadratic (phi_eq is linear in
  I), and the flow is non-associated: the plastic shear y / mu comes with
  a plastic log volume change tan(psi) y / mu, taken from the elastic
  volume (dense sand dilates, its pressure rises; loose sand compacts).
  With K = 0 it is the plain return.

  Args:
    F, volume_correction, mu, lam: as ``project``.
    rheology: the parameters; dt: the substep (s).
    volume_fraction: [...] phi, with the compressible law only.

  Returns:
    (F, volume_correction) after projection, same shapes.
  """
  trace, dev = log_strain(F)
  trace_c = trace + volume_correction
  dev_norm = _deviatoric_norm(dev)
  p = -(mu + lam) * trace_c
  tau_trial = _SQRT2 * mu * dev_norm
  # Separating sand (p <= 0) is _return_map's; only compressed sand yields.
  compressed = trace_c < 0
  p_safe = jnp.where(compressed, p, 1.0)
  c = rheology.grain_diameter / (
      mu * dt * jnp.sqrt(p_safe / rheology.grain_density))
  dilation = None
  if rheology.dilatancy is not None:
    # mu(I) + tan psi, tan psi = K (phi - phi_eq(I)): a part at rest,
    # mu_s + K (phi - phi_max) (kept >= 0: no negative friction however
    # loose), and a slope K (phi_max - phi_min) in I.
    k = rheology.dilatancy
    slope = k * (rheology.phi_max - rheology.phi_min)
    mu_rest = jnp.maximum(
        rheology.mu_s + k * (volume_fraction - rheology.phi_max), 0.0)
    yielding = jnp.logical_and(compressed, tau_trial > mu_rest * p)
    drop = _quadratic_drop(tau_trial, p, c, rheology, yielding, mu_rest,
                           slope)
    # The plastic volume change tan(psi) times the plastic shear drop / mu,
    # at the return's I = c y; a compaction releases at most the pressure.
    tan_psi = mu_rest - rheology.mu_s + slope * (c * drop)
    dilation = jnp.where(yielding, jnp.maximum(tan_psi * drop / mu, trace_c),
                         0.0)
  elif rheology.I_N is None:
    yielding = jnp.logical_and(compressed, tau_trial > rheology.mu_s * p)
    drop = _quadratic_drop(tau_trial, p, c, rheology, yielding)
  else:
    # The return lands at I >= I_N iff the plain law's residual at I_N,
    # tau_trial - I_N / c - mu(I_N) p, is >= 0 (it decreases in I).
    upper = jnp.logical_and(compressed, tau_trial - rheology.I_N / c >=
                            mu_of_i(rheology.I_N, rheology) * p_safe)
    low = (compressed & ~upper &
           (tau_trial**2 * _W_MAX > rheology.alpha_reg * p_safe**2))
    yielding = upper | low
    drop = jnp.where(upper, _quadratic_drop(tau_trial, p, c, rheology, upper),
                     _regularized_drop(tau_trial, p, c, rheology, low))
  delta_gamma = jnp.where(yielding, drop / (_SQRT2 * mu), 0.0)
  F, volume_correction = _return_map(F, trace_c, dev, dev_norm, delta_gamma)
  if dilation is not None:
    # The elastic log volume loses what the plastic flow gains: a dilating
    # sample's pressure rises until it expands, a compacting one's falls.
    F = F * jnp.exp(-dilation / 2)[..., None, None]
  return F, volume_correction


def project_principal(F, volume_correction, mu, lam, alpha):
  """Reference: the same return mapping on singular values (Klar et al.).

  Not differentiable at equal singular values; used to check ``project``.
  """
  u, sigma, v = linalg.svd2x2(F)
  eps = jnp.log(jnp.maximum(sigma, 1e-6))
  trace_c = eps.sum(-1) + volume_correction
  eps_hat = eps - eps.mean(-1, keepdims=True)
  norm = jnp.linalg.norm(eps_hat, axis=-1)
  delta_gamma = norm + (lam + mu) / mu * alpha * trace_c
  expand = trace_c >= 0
  on_cone = jnp.logical_and(~expand, delta_gamma > 0)
  shrink = jnp.where(on_cone, delta_gamma, 0.0) / jnp.maximum(norm, 1e-20)
  h = jnp.where(expand[..., None], 0.0, eps - shrink[..., None] * eps_hat)
  F_new = jnp.einsum("...ij,...j,...kj->...ik", u, jnp.exp(h), v)
  return F_new, jnp.where(expand, trace_c, 0.0)
