"""A Taichi (CPU) MLS-MPM peer of ``mpm.solver.substep``, for the benchmark.

Timed and checked by the MPM benchmark (``mpm_benchmark``: ``--what=mpm``).

Written for the benchmark, not a second solver to maintain: the same scene and
physics as the JAX solver, so that the two can be timed against each other
and checked against each other.

* the same grid (``setup.spec``: ``GridSpec.covering(width, height, dx)``,
  three cells of padding), dt and substeps per frame;
* quadratic B-spline APIC P2G/G2P with the MLS-MPM stress momentum
  ``-dt V 4/dx^2 tau``;
* Hencky elasticity, tau = U diag(2 mu eps + lam tr eps) U^T, eps = log sigma
  from a 2 x 2 SVD (the closed form of ``mpm.linalg.svd2x2`` by default;
  ``ti.svd`` on request, which is not the same physics: see ``SVD_KINDS``);
* the Drucker-Prager return map with volume correction on the singular values,
  exactly as ``mpm.constitutive.project_principal``: alpha = sin(phi)/sqrt(2),
  delta_gamma = ||eps_hat|| + (lam + mu)/mu alpha (tr eps + v_c);
* gravity on grid velocities, then the soft-weighted Coulomb projection
  (``mpm.boundary.coulomb``: solid, x-wall, y-wall) on the nodes listed in
  ``setup.field``, copied into Taichi fields;
* particles that stepped into a solid pushed back along the signed distance
  interpolated from the nodes (``mpm.boundary.project_particles``, when the
  field carries the node distances ``phi``), then clamped to the domain;
* F <- (I + dt C) F, and the largest speed of the substep (as the JAX substep
  returns it).

Padding particles (zero volume) and padding boundary entries (zero weights)
of ``mpm.setup``'s buckets are carried along as the JAX solver carries them.

Taichi is an optional dependency (``pip install -e .[bench]``): this module
imports it at the top, so import this module lazily.

Shapes: N particles, B boundary nodes, grid (nx, ny).
"""

import math

import numpy as np
import taichi as ti

_initialised = False

# ti.svd (2D) drops the off-diagonal of the stretch when it is below 1e-5
# (taichi/_funcs.py, _svd2d), an absolute threshold: near F = I, where sand
# sits, shear strains below 1e-5 are zeroed at every projection, so small
# elastic shear never builds up. The closed form keeps F's float32 precision.
SVD_KINDS = ("closed_form", "taichi")


@ti.func
def _rotation(angle):
  c, s = ti.cos(angle), ti.sin(angle)
  return ti.Matrix([[c, -s], [s, c]])


@ti.func
def _svd2x2(a):
  """Closed-form 2 x 2 SVD (Blinn), as ``mpm.linalg.svd2x2``."""
  e = (a[0, 0] + a[1, 1]) / 2
  f = (a[0, 0] - a[1, 1]) / 2
  g = (a[1, 0] + a[0, 1]) / 2
  h = (a[1, 0] - a[0, 1]) / 2
  q = ti.sqrt(e * e + h * h)
  r = ti.sqrt(f * f + g * g)
  a1 = ti.atan2(g, f)
  a2 = ti.atan2(h, e)
  u = _rotation((a2 + a1) / 2)
  v = _rotation((a1 - a2) / 2)
  s2 = q - r
  if s2 < 0:  # a reflection: its sign goes into V
    v[0, 1] = -v[0, 1]
    v[1, 1] = -v[1, 1]
  return u, ti.Matrix([[q + r, 0.0], [0.0, ti.abs(s2)]]), v


def init(num_threads: int | None = None) -> dict:
  """Initialises Taichi's CPU backend once per process (f32, quiet).

  Args:
    num_threads: CPU threads for Taichi's parallel loops (default: all).

  Returns:
    A description of the backend for the benchmark record.
  """
  global _initialised  # pylint: disable=global-statement
  if not _initialised:
    kwargs = {"cpu_max_num_threads": num_threads} if num_threads else {}
    ti.init(arch=ti.cpu, default_fp=ti.f32, default_ip=ti.i32,
            log_level=ti.WARN, **kwargs)
    _initialised = True
  return {"taichi_version": ".".join(map(str, ti.__version__)),
          "arch": "cpu", "num_threads": num_threads or "all"}


@ti.data_oriented
class TaichiMPM:
  """One scene's MLS-MPM state and substep in Taichi fields.

  Built from an ``mpm.Setup``; every constant (dt, moduli, friction, grid)
  is taken from it, so the peer runs the same discretisation. Call
  :func:`init` first.

  Args:
    setup: the scene's ``mpm.Setup``.
    svd: "closed_form" (default; the 2 x 2 closed form of
      ``mpm.linalg.svd2x2``) or "taichi" (``ti.svd``). See ``SVD_KINDS``.
  """

  def __init__(self, setup, svd: str = "closed_form"):
    if svd not in SVD_KINDS:
      raise ValueError(f"svd: unknown {svd!r}; allowed: {list(SVD_KINDS)}")
    self.svd = svd
    spec = setup.spec
    p = setup.params
    f = lambda a: float(np.asarray(a))
    mu = f(p.youngs_modulus) / (2 * (1 + f(p.poisson_ratio)))
    lam = f(p.youngs_modulus) * f(p.poisson_ratio) / (
        (1 + f(p.poisson_ratio)) * (1 - 2 * f(p.poisson_ratio)))
    # Python floats below are compile-time constants of the kernels.
    self.dt = f(p.dt)
    self.dx = float(spec.dx)
    self.inv_dx = 1.0 / spec.dx
    self.origin = tuple(float(o) for o in spec.origin)
    self.mu, self.lam = mu, lam
    self.alpha = math.sin(f(p.friction_angle)) / math.sqrt(2.0)
    self.boundary_friction = f(p.boundary_friction)
    self.wall_friction = f(p.wall_friction)
    self.gravity = tuple(float(g) for g in np.asarray(p.gravity))
    self.domain = tuple(float(d) for d in np.asarray(p.domain))
    self.density = f(p.density)
    self.n_substeps = setup.n_substeps
    self.nx, self.ny = spec.shape

    state, field = setup.state, setup.field
    n = state.x.shape[0]
    nb = field.index.shape[0]
    self.n_particles = n
    self.n_boundary = nb

    # Particles.
    self.x = ti.Vector.field(2, ti.f32, n)
    self.v = ti.Vector.field(2, ti.f32, n)
    self.C = ti.Matrix.field(2, 2, ti.f32, n)
    self.F = ti.Matrix.field(2, 2, ti.f32, n)
    self.vc = ti.field(ti.f32, n)
    self.vol = ti.field(ti.f32, n)
    # Grid.
    self.grid_mv = ti.Vector.field(2, ti.f32, spec.shape)
    self.grid_m = ti.field(ti.f32, spec.shape)
    # Boundary nodes (copied from the JAX BoundaryField).
    self.b_index = ti.field(ti.i32, nb)
    self.b_solid_normal = ti.Vector.field(2, ti.f32, nb)
    self.b_solid_weight = ti.field(ti.f32, nb)
    self.b_wall_normal = ti.Vector.field(2, ti.f32, nb)
    self.b_wall_weight = ti.Vector.field(2, ti.f32, nb)
    self.max_speed_sq = ti.field(ti.f32, ())
    # Signed distance to the solids at every node, for the particle
    # projection (present when the solver has one).
    self.project_particles = hasattr(field, "phi")
    self.grid_phi = ti.field(ti.f32, spec.shape)
    if self.project_particles:
      self.grid_phi.from_numpy(
          np.asarray(field.phi, np.float32).reshape(spec.shape))

    self.b_index.from_numpy(np.asarray(field.index, np.int32))
    self.b_solid_normal.from_numpy(np.asarray(field.solid_normal, np.float32))
    self.b_solid_weight.from_numpy(np.asarray(field.solid_weight, np.float32))
    self.b_wall_normal.from_numpy(np.asarray(field.wall_normal, np.float32))
    self.b_wall_weight.from_numpy(np.asarray(field.wall_weight, np.float32))
    self._initial = {k: np.asarray(getattr(state, k), np.float32) for k in
                     ("x", "v", "C", "F", "volume_correction", "volume")}
    self.reset()

  def reset(self):
    """Back to the setup's initial particle state."""
    s = self._initial
    self.x.from_numpy(s["x"])
    self.v.from_numpy(s["v"])
    self.C.from_numpy(s["C"])
    self.F.from_numpy(s["F"])
    self.vc.from_numpy(s["volume_correction"])
    self.vol.from_numpy(s["volume"])
    ti.sync()

  # ------------------------------------------------------------- kernels ---

  @ti.func
  def _clear_grid(self):
    for i, j in self.grid_m:
      self.grid_mv[i, j] = ti.Vector([0.0, 0.0])
      self.grid_m[i, j] = 0.0
    self.max_speed_sq[None] = 0.0

  @ti.func
  def _svd(self, F):
    """F = U diag(sig) V^T: ``ti.svd`` or the closed form of mpm.linalg."""
    U = ti.Matrix.identity(ti.f32, 2)
    sig = ti.Matrix.identity(ti.f32, 2)
    V = ti.Matrix.identity(ti.f32, 2)
    if ti.static(self.svd == "taichi"):
      U, sig, V = ti.svd(F, ti.f32)
    else:
      U, sig, V = _svd2x2(F)
    return U, sig, V

  @ti.func
  def _kirchhoff(self, F):
    U, sig, _ = self._svd(F)
    e0 = ti.log(ti.max(sig[0, 0], 1e-6))
    e1 = ti.log(ti.max(sig[1, 1], 1e-6))
    tr = e0 + e1
    t0 = 2 * self.mu * e0 + self.lam * tr
    t1 = 2 * self.mu * e1 + self.lam * tr
    return U @ ti.Matrix([[t0, 0.0], [0.0, t1]]) @ U.transpose()

  @ti.func
  def _p2g(self):
    ox, oy = self.origin
    for p in self.x:
      vol = self.vol[p]
      mass = self.density * vol
      xg = (self.x[p] - ti.Vector([ox, oy])) * self.inv_dx
      base = ti.floor(xg - 0.5)
      fx = xg - base
      w = [0.5 * (1.5 - fx)**2, 0.75 - (fx - 1.0)**2, 0.5 * (fx - 0.5)**2]
      tau = self._kirchhoff(self.F[p])
      affine = (-self.dt * 4.0 * self.inv_dx * self.inv_dx * vol) * tau + (
          mass * self.C[p])
      b = ti.cast(base, ti.i32)
      for i, j in ti.static(ti.ndrange(3, 3)):
        dpos = (ti.Vector([i, j], ti.f32) - fx) * self.dx
        weight = w[i][0] * w[j][1]
        self.grid_mv[b[0] + i, b[1] + j] += weight * (
            mass * self.v[p] + affine @ dpos)
        self.grid_m[b[0] + i, b[1] + j] += weight * mass

  @ti.func
  def _grid_update(self):
    gx, gy = self.gravity
    for i, j in self.grid_m:
      m = self.grid_m[i, j]
      v = ti.Vector([0.0, 0.0])
      if m > 0:
        v = self.grid_mv[i, j] / m
      self.grid_mv[i, j] = v + self.dt * ti.Vector([gx, gy])

  @ti.func
  def _coulomb(self, v, normal, weight, mu):
    v_n = v.dot(normal)
    v_t = v - v_n * normal
    t_sq = v_t.dot(v_t)
    t_norm = ti.sqrt(t_sq) if t_sq > 0 else 1.0
    scale = ti.max(0.0, 1.0 + mu * v_n / t_norm)
    projected = v
    if v_n < 0:
      projected = scale * v_t
    return v + weight * (projected - v)

  @ti.func
  def _boundary(self):
    for k in self.b_index:
      node = self.b_index[k]
      i = node // self.ny
      j = node % self.ny
      v = self.grid_mv[i, j]
      v = self._coulomb(v, self.b_solid_normal[k], self.b_solid_weight[k],
                        self.boundary_friction)
      wn = self.b_wall_normal[k]
      ww = self.b_wall_weight[k]
      v = self._coulomb(v, ti.Vector([wn[0], 0.0]), ww[0], self.wall_friction)
      v = self._coulomb(v, ti.Vector([0.0, wn[1]]), ww[1], self.wall_friction)
      self.grid_mv[i, j] = v

  @ti.func
  def _project(self, F, vc):
    U, sig, V = self._svd(F)
    e0 = ti.log(ti.max(sig[0, 0], 1e-6))
    e1 = ti.log(ti.max(sig[1, 1], 1e-6))
    trace_c = e0 + e1 + vc
    mean = 0.5 * (e0 + e1)
    h0, h1 = e0 - mean, e1 - mean
    norm = ti.sqrt(h0 * h0 + h1 * h1)
    delta_gamma = norm + (self.lam + self.mu) / self.mu * self.alpha * trace_c
    F_new = F
    vc_new = 0.0
    if trace_c >= 0:  # expansion: stress free, remember the volume
      F_new = U @ V.transpose()
      vc_new = trace_c
    else:
      shrink = 0.0
      if delta_gamma > 0:  # on the cone: shrink the deviatoric strain
        shrink = delta_gamma / ti.max(norm, 1e-20)
      s0 = ti.exp(e0 - shrink * h0)
      s1 = ti.exp(e1 - shrink * h1)
      F_new = U @ ti.Matrix([[s0, 0.0], [0.0, s1]]) @ V.transpose()
    return F_new, vc_new

  @ti.func
  def _g2p(self):
    ox, oy = self.origin
    wx, wy = self.domain
    for p in self.x:
      xg = (self.x[p] - ti.Vector([ox, oy])) * self.inv_dx
      base = ti.floor(xg - 0.5)
      fx = xg - base
      w = [0.5 * (1.5 - fx)**2, 0.75 - (fx - 1.0)**2, 0.5 * (fx - 0.5)**2]
      b = ti.cast(base, ti.i32)
      new_v = ti.Vector([0.0, 0.0])
      new_C = ti.Matrix([[0.0, 0.0], [0.0, 0.0]])
      phi = 0.0
      grad = ti.Vector([0.0, 0.0])
      for i, j in ti.static(ti.ndrange(3, 3)):
        dpos = (ti.Vector([i, j], ti.f32) - fx) * self.dx
        weight = w[i][0] * w[j][1]
        wv = weight * self.grid_mv[b[0] + i, b[1] + j]
        new_v += wv
        new_C += wv.outer_product(dpos)
        if ti.static(self.project_particles):
          w_phi = weight * self.grid_phi[b[0] + i, b[1] + j]
          phi += w_phi
          grad += w_phi * dpos
      new_C *= 4.0 * self.inv_dx * self.inv_dx
      if self.vol[p] <= 0:  # padding particle: does not move
        new_v = ti.Vector([0.0, 0.0])
        new_C = ti.Matrix([[0.0, 0.0], [0.0, 0.0]])
      self.v[p] = new_v
      self.C[p] = new_C
      x = self.x[p] + self.dt * new_v
      if ti.static(self.project_particles):
        # Out of the solid along the MLS gradient of the node distances,
        # the distance extrapolated along the step.
        grad *= 4.0 * self.inv_dx * self.inv_dx
        phi_new = phi + grad.dot(x - self.x[p])
        g_sq = grad.dot(grad)
        inv = 0.0
        if g_sq > 0:
          inv = 1.0 / ti.sqrt(g_sq)
        x += ti.max(-phi_new, 0.0) * inv * inv * grad
      self.x[p] = ti.Vector([ti.min(ti.max(x[0], 0.0), wx),
                             ti.min(ti.max(x[1], 0.0), wy)])
      F = self.F[p] + self.dt * new_C @ self.F[p]
      F, vc = self._project(F, self.vc[p])
      self.F[p] = F
      self.vc[p] = vc
      ti.atomic_max(self.max_speed_sq[None], new_v.dot(new_v))

  # ------------------------------------------------------------- drivers ---

  @ti.kernel
  def substep(self):
    """One substep dt, one kernel launch (asynchronous: ``ti.sync()``).

    Each stage's top-level loop is a parallel task; tasks run in order.
    """
    self._clear_grid()
    self._p2g()
    self._grid_update()
    self._boundary()
    self._g2p()

  def advance(self, n_frames: int = 1) -> np.ndarray:
    """Runs ``n_frames`` frames; returns positions float32 [n_frames, N, 2]."""
    out = np.empty((n_frames, self.n_particles, 2), np.float32)
    for k in range(n_frames):
      for _ in range(self.n_substeps):
        self.substep()
      out[k] = self.x.to_numpy()
    return out

  def run_substeps(self, n: int):
    """Runs ``n`` substeps and waits for them to finish."""
    for _ in range(n):
      self.substep()
    ti.sync()


def sync():
  ti.sync()
