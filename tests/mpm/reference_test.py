"""The optimised MLS-MPM substep against the straightforward one it replaced.

`mpm.transfer` computes each particle's stencil index once per particle,
packs node velocity and signed distance into one gather and scatters through
`lax` with unsigned indices (docs/performance.md, "MPM solver"). These tests
keep the plain formulation (one int32 index per stencil node, `jnp`
indexing, one gather per field) and check that the two agree: the indices
exactly, the transfers bit for bit, and a rollout of the paper scene to
1e-6 m.
"""

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from experiments.benchmarks import scenes
from mpm import boundary
from mpm import constitutive
from mpm import geometry
from mpm import solver
from mpm import transfer

SPEC = transfer.GridSpec.covering(0.3, 0.25, 0.02)
N = 300


def _index(x, spec, window_at=None):
  """The plain stencil index: int32 [N, 9], per stencil node."""
  xg = (x - jnp.asarray([spec.origin], x.dtype)) * (1.0 / spec.dx)
  b = jnp.floor(xg - 0.5).astype(jnp.int32)
  if window_at is not None:
    b = b - window_at[None, :]
  oi = jnp.arange(3, dtype=jnp.int32)
  column = b[:, :1, None] + oi[None, :, None]
  if spec.periodic_x:
    column = column % spec.shape[0]
  return (column * spec.shape[1] + b[:, 1:, None] +
          oi[None, None, :]).reshape(-1, 9)


def _p2g(st, mass, momentum, affine, n_nodes):
  ox, oy = st.offset[..., 0], st.offset[..., 1]
  a = affine[:, None]
  mv = momentum[:, None, :] + jnp.stack(
      [a[..., 0, 0] * ox + a[..., 0, 1] * oy,
       a[..., 1, 0] * ox + a[..., 1, 1] * oy], -1)
  values = jnp.concatenate([st.weight[..., None] * mv,
                            (st.weight * mass[:, None])[..., None]], -1)
  values = jax.lax.optimization_barrier(values)
  return jnp.zeros((n_nodes, 3), values.dtype).at[st.index.reshape(-1)].add(
      values.reshape(-1, 3), mode="promise_in_bounds")


def _g2p(st, grid_v, dx):
  gv = grid_v.at[st.index].get(mode="promise_in_bounds")
  wv = st.weight[..., None] * gv
  C = (4.0 / dx**2) * jnp.sum(wv[..., :, None] * st.offset[..., None, :], 1)
  return jnp.sum(wv, axis=1), C


def _project_particles(field, st, x_new, x_old, dx):
  w_phi = st.weight * field.phi[st.index]
  phi = jnp.sum(w_phi, -1)
  grad = (4.0 / dx**2) * jnp.sum(w_phi[..., None] * st.offset, 1)
  phi_new = phi + jnp.sum(grad * (x_new - x_old), -1)
  g_sq = jnp.sum(grad * grad, -1)
  inv = jax.lax.rsqrt(jnp.where(g_sq > 0, g_sq, 1.0)) * (g_sq > 0)
  return geometry.push_out(x_new, phi_new * inv, grad * inv[:, None])


def _substep(state, params, field, spec):
  """`solver.substep` (Drucker-Prager, whole grid) in the plain form."""
  dt = params.dt
  mu, lam = constitutive.lame_parameters(params.youngs_modulus,
                                         params.poisson_ratio)
  alpha = constitutive.friction_coefficient(params.friction_angle)
  active = (state.volume > 0).astype(state.x.dtype)
  mass = params.density * state.volume
  st = transfer.stencil(state.x, spec)
  st = st.replace(index=_index(state.x, spec))
  tau = constitutive.kirchhoff_stress(state.F, mu, lam)
  affine = ((-dt * 4.0 / spec.dx**2) * state.volume[:, None, None] * tau +
            mass[:, None, None] * state.C)
  grid = _p2g(st, mass, mass[:, None] * state.v, affine, spec.n_nodes)
  min_mass = solver._MIN_NODE_MASS * jnp.max(mass)  # pylint: disable=protected-access
  grid_v = transfer.grid_velocity(grid, min_mass)
  grid_v = grid_v + dt * params.gravity[None, :]
  grid_v = boundary.apply(field, grid_v, params.boundary_friction,
                          params.wall_friction)
  v, C = _g2p(st, grid_v, spec.dx)
  v = v * active[:, None]
  C = C * active[:, None, None]
  x = _project_particles(field, st, state.x + dt * v, state.x, spec.dx)
  x = jnp.clip(x, 0.0, params.domain[None, :])
  F = state.F + dt * jnp.sum(C[..., :, :, None] * state.F[..., None, :, :], -2)
  F, vc = constitutive.project(F, state.volume_correction, mu, lam, alpha)
  return state.replace(x=x, v=v, C=C, F=F, volume_correction=vc)


def _particles(seed):
  rng = np.random.default_rng(seed)
  x = rng.uniform([0.0, 0.0], [0.3, 0.25], (N, 2)).astype(np.float32)
  mass = rng.uniform(0.5, 2.0, N).astype(np.float32)
  v = rng.normal(size=(N, 2)).astype(np.float32)
  affine = (rng.normal(size=(N, 2, 2)) * 10.0).astype(np.float32)
  return tuple(map(jnp.asarray, (x, mass, v, affine)))


class TransferTest(parameterized.TestCase):

  @parameterized.parameters(
      (SPEC, None),
      (SPEC, (3, 2)),
      (transfer.GridSpec(0.02, (15, 19), (0.0, -0.06), periodic_x=True),
       None))
  def test_stencil_index_is_the_plain_one(self, spec, window_at):
    x, _, _, _ = _particles(0)
    at = None if window_at is None else jnp.asarray(window_at, jnp.int32)
    got = jax.jit(transfer.stencil, static_argnums=1)(x, spec, at).index
    np.testing.assert_array_equal(got, _index(x, spec, at))

  def test_p2g_and_g2p_are_bit_for_bit_the_plain_ones(self):
    x, mass, v, affine = _particles(1)
    st = jax.jit(transfer.stencil, static_argnums=1)(x, SPEC)
    p2g = jax.jit(transfer.p2g, static_argnums=4)
    want = jax.jit(_p2g, static_argnums=4)(st, mass, mass[:, None] * v,
                                           affine, SPEC.n_nodes)
    got = p2g(st, mass, mass[:, None] * v, affine, SPEC.n_nodes)
    np.testing.assert_array_equal(got, want)
    grid_v = jnp.asarray(np.random.default_rng(2).normal(
        size=(SPEC.n_nodes, 2)), jnp.float32)
    for a, b in zip(jax.jit(transfer.g2p, static_argnums=2)(st, grid_v,
                                                            SPEC.dx),
                    jax.jit(_g2p, static_argnums=2)(st, grid_v, SPEC.dx)):
      np.testing.assert_array_equal(a, b)


class RolloutTest(absltest.TestCase):

  def test_paper_scene_positions_are_the_plain_substeps(self):
    # 10 frames (140 substeps) of the paper scene: the sand starts to move.
    setup = mpm.setup(mpm.Scene.from_dict(
        {**scenes.PAPER_SCENE, "num_frames": 11}))
    n = 10 * setup.n_substeps

    @jax.jit
    def plain(state, params, field):
      return jax.lax.fori_loop(
          0, n, lambda _, s: _substep(s, params, field, setup.spec), state).x

    @jax.jit
    def optimised(state, params, field):
      return jax.lax.fori_loop(
          0, n, lambda _, s: solver.substep(s, params, field, setup.spec)[0],
          state).x

    args = (setup.state, setup.params, setup.field)
    want, got = plain(*args), optimised(*args)
    moved = np.abs(np.asarray(want) - np.asarray(setup.state.x)).max()
    self.assertGreater(moved, 1e-3)
    np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


if __name__ == "__main__":
  absltest.main()
