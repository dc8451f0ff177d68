"""Tests for `mpm.transfer`."""

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

from mpm import transfer

SPEC = transfer.GridSpec.covering(0.3, 0.25, 0.02)
N = 200

_stencil = jax.jit(transfer.stencil, static_argnums=1)
_p2g = jax.jit(transfer.p2g, static_argnums=4)
_g2p = jax.jit(transfer.g2p, static_argnums=2)


def _particles(seed, n=N, dtype=np.float64):
  rng = np.random.default_rng(seed)
  x = rng.uniform([0.0, 0.0], [0.3, 0.25], (n, 2))
  mass = rng.uniform(0.5, 2.0, n)
  v = rng.normal(size=(n, 2))
  c = rng.normal(size=(n, 2, 2)) * 10.0  # 1/s; C dx ~ v
  return tuple(a.astype(dtype) for a in (x, mass, v, c))


def _round_trip(x, mass, v, c):
  """P2G of APIC momentum, grid velocities, G2P (no forces or conditions)."""
  st = _stencil(jnp.asarray(x), SPEC)
  grid = _p2g(st, jnp.asarray(mass), jnp.asarray(mass[:, None] * v),
              jnp.asarray(mass[:, None, None] * c), SPEC.n_nodes)
  grid = np.asarray(grid)
  node_mass = grid[:, 2]
  node_mom = grid[:, :2]
  safe = np.where(node_mass > 0, node_mass, 1.0)
  grid_v = np.where(node_mass[:, None] > 0, node_mom / safe[:, None], 0.0)
  v_new, c_new = _g2p(st, jnp.asarray(grid_v), SPEC.dx)
  return grid, grid_v, np.asarray(v_new), np.asarray(c_new)


def _angular_momentum(x, mass, v, c):
  """APIC particle angular momentum (z): m (x cross v) + m dx^2/4 (C_yx - C_xy).

  The second term is the spin of the affine field: sum_i w (x_i - x_p) cross
  (C (x_i - x_p)) with the quadratic B-spline moment dx^2/4 I.
  """
  spin = SPEC.dx**2 / 4 * (c[:, 1, 0] - c[:, 0, 1])
  return np.sum(mass * (x[:, 0] * v[:, 1] - x[:, 1] * v[:, 0] + spin))


class StencilTest(parameterized.TestCase):

  def setUp(self):
    super().setUp()
    x, _, _, _ = _particles(0, dtype=np.float32)
    # Include the corners of the domain and exact node positions.
    self.x = np.concatenate([x, [[0.0, 0.0], [0.3, 0.25], [0.1, 0.12],
                                 [0.05, 0.0]]]).astype(np.float32)
    self.st = _stencil(jnp.asarray(self.x), SPEC)

  def test_partition_of_unity(self):
    np.testing.assert_allclose(np.sum(self.st.weight, 1), 1.0, atol=1e-6,
                               rtol=0)
    self.assertTrue(np.all(np.asarray(self.st.weight) >= 0))

  def test_linear_reproduction(self):
    # sum_i w_i (x_i - x_p) = 0: linear fields are reproduced exactly.
    first = np.sum(np.asarray(self.st.weight)[..., None] *
                   np.asarray(self.st.offset), 1)
    np.testing.assert_allclose(first, 0.0, atol=1e-8, rtol=0)

  def test_second_moment(self):
    # sum_i w_i d d^T = dx^2 / 4 I: the inertia tensor behind APIC's 4 / dx^2.
    d = np.asarray(self.st.offset, np.float64)
    w = np.asarray(self.st.weight, np.float64)
    second = np.einsum("ns,nsi,nsj->nij", w, d, d)
    np.testing.assert_allclose(
        second, np.broadcast_to(SPEC.dx**2 / 4 * np.eye(2), second.shape),
        atol=1e-9, rtol=0)

  def test_offsets_point_at_nodes(self):
    index = np.asarray(self.st.index)
    self.assertTrue(np.all((index >= 0) & (index < SPEC.n_nodes)))
    nodes = SPEC.node_positions()[index]
    np.testing.assert_allclose(nodes - self.x[:, None, :], self.st.offset,
                               atol=1e-6, rtol=0)
    # The 9 nodes are distinct and within 1.5 cells of the particle.
    self.assertTrue(all(len(set(row)) == 9 for row in index.tolist()))
    self.assertLessEqual(np.max(np.abs(self.st.offset)), 1.5 * SPEC.dx + 1e-6)


class TransferTest(parameterized.TestCase):

  @parameterized.parameters(0, 1, 2)
  def test_conserves_mass_and_momentum(self, seed):
    with jax.enable_x64(True):
      x, mass, v, c = _particles(seed)
      grid, grid_v, v_new, _ = _round_trip(x, mass, v, c)
    # float64: sums of O(100) terms of O(1).
    np.testing.assert_allclose(grid[:, 2].sum(), mass.sum(), rtol=1e-12,
                               atol=0)
    p0 = (mass[:, None] * v).sum(0)
    np.testing.assert_allclose(grid[:, :2].sum(0), p0, rtol=0, atol=1e-10)
    np.testing.assert_allclose((mass[:, None] * v_new).sum(0), p0, rtol=0,
                               atol=1e-10)
    np.testing.assert_allclose((grid[:, 2:] * grid_v).sum(0), p0, rtol=0,
                               atol=1e-10)

  @parameterized.parameters(0, 1, 2)
  def test_conserves_angular_momentum(self, seed):
    with jax.enable_x64(True):
      x, mass, v, c = _particles(seed)
      grid, grid_v, v_new, c_new = _round_trip(x, mass, v, c)
    nodes = SPEC.node_positions()
    l0 = _angular_momentum(x, mass, v, c)
    l_grid = np.sum(grid[:, 2] * (nodes[:, 0] * grid_v[:, 1] -
                                  nodes[:, 1] * grid_v[:, 0]))
    l1 = _angular_momentum(x, mass, v_new, c_new)
    np.testing.assert_allclose(l_grid, l0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(l1, l0, rtol=0, atol=1e-10)
    # Without the affine spin term (PIC), the round trip would lose some.
    self.assertGreater(abs(_angular_momentum(x, mass, v_new, 0 * c_new) - l0),
                       1e-4)

  def test_float32_conservation(self):
    x, mass, v, c = _particles(3, dtype=np.float32)
    grid, _, v_new, _ = _round_trip(x, mass, v, c)
    np.testing.assert_allclose(grid[:, 2].sum(), mass.sum(), rtol=1e-5, atol=0)
    p0 = (mass[:, None] * v).sum(0)
    # float32: ~1e-7 relative per term, sum of |m v| ~ 200.
    np.testing.assert_allclose((mass[:, None] * v_new).sum(0), p0, rtol=0,
                               atol=2e-4)

  def test_uniform_velocity_round_trips(self):
    x, mass, _, _ = _particles(4, dtype=np.float32)
    v = np.broadcast_to(np.float32([0.7, -1.3]), (N, 2))
    _, _, v_new, c_new = _round_trip(x, mass, v, np.zeros((N, 2, 2),
                                                          np.float32))
    np.testing.assert_allclose(v_new, v, atol=1e-6, rtol=0)
    np.testing.assert_allclose(c_new, 0.0, atol=1e-3, rtol=0)  # 1/s

  def test_affine_velocity_round_trips(self):
    # APIC reproduces v(x) = v0 + G x exactly, C included.
    with jax.enable_x64(True):
      x, mass, _, _ = _particles(5)
      g = np.array([[0.5, -2.0], [1.5, 0.3]])
      v = np.array([0.2, -0.1]) + x @ g.T
      c = np.broadcast_to(g, (N, 2, 2))
      _, _, v_new, c_new = _round_trip(x, mass, v, c)
    np.testing.assert_allclose(v_new, v, atol=1e-12, rtol=0)
    np.testing.assert_allclose(c_new, c, atol=1e-9, rtol=0)

  def test_zero_mass_particles_are_ignored(self):
    x, mass, v, c = _particles(6, dtype=np.float32)
    mass[::2] = 0.0
    grid, _, _, _ = _round_trip(x, mass, v, c)
    grid_ref, _, _, _ = _round_trip(x[1::2], mass[1::2], v[1::2], c[1::2])
    np.testing.assert_allclose(grid, grid_ref, atol=1e-5, rtol=0)


class GridVelocityTest(absltest.TestCase):

  def test_gradient_is_finite_at_nodes_a_stencil_barely_touches(self):
    # Node 0: ordinary; node 1: 1e-25 kg, a particle's weight ~1e-24 (the
    # README's heap meets such nodes after ~20 frames); node 2: empty.
    grid = jnp.asarray([[0.3, -0.2, 0.5], [2e-25, 1e-25, 1e-25],
                        [0.0, 0.0, 0.0]], jnp.float32)
    min_mass = 1e-12
    # With the old threshold (m > 0) the derivative -p / m^2 at node 1 is
    # inf, and a zero cotangent makes it NaN.
    naive = lambda g: jnp.where(g[:, 2:] > 0, g[:, :2] / jnp.where(
        g[:, 2:] > 0, g[:, 2:], 1.0), 0.0)
    ct = jnp.asarray([[1.0, 1.0], [0.0, 0.0], [0.0, 0.0]], jnp.float32)
    self.assertFalse(np.all(np.isfinite(jax.vjp(naive, grid)[1](ct)[0])))

    v, vjp = jax.vjp(lambda g: transfer.grid_velocity(g, min_mass), grid)
    np.testing.assert_allclose(v, [[0.6, -0.4], [0.0, 0.0], [0.0, 0.0]],
                               rtol=1e-6)
    (g,) = vjp(ct)
    self.assertTrue(np.all(np.isfinite(g)))
    # d(p / m) = (dp - v dm) / m at the ordinary node; zero elsewhere.
    np.testing.assert_allclose(g[0], [2.0, 2.0, -(0.6 - 0.4) / 0.5],
                               rtol=1e-6)
    np.testing.assert_array_equal(g[1:], 0.0)


if __name__ == "__main__":
  absltest.main()
