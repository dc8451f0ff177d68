"""Tests for `mpm.linalg`."""

from absl.testing import absltest
from absl.testing import parameterized
import jax.numpy as jnp
import numpy as np

from mpm import linalg

# float32 closed form against float64 LAPACK: a few ulps of the largest
# singular value (the entries below are O(1)).
ATOL = 2e-5


def _degenerate():
  return {
      "identity": np.eye(2),
      "zero": np.zeros((2, 2)),
      "rank_one": np.outer([1.0, 2.0], [3.0, -1.0]),
      "equal_singular_values": 2.5 * np.array([[np.cos(0.7), -np.sin(0.7)],
                                               [np.sin(0.7), np.cos(0.7)]]),
      "negative_determinant": np.array([[0.3, 1.2], [0.9, -0.4]]),
      "reflection": np.diag([1.0, -1.0]),
      "near_zero_singular_value": np.array([[1.0, 1.0], [1.0, 1.0 + 1e-6]]),
      "diagonal_unsorted": np.diag([0.5, 3.0]),
      "negative_identity": -np.eye(2),
      "shear": np.array([[1.0, 0.8], [0.0, 1.0]]),
  }


class Svd2x2Test(parameterized.TestCase):

  def _check(self, a):
    a = np.asarray(a, np.float32)
    u, s, v = map(np.asarray, linalg.svd2x2(jnp.asarray(a)))
    s_ref = np.linalg.svd(a.astype(np.float64), compute_uv=False)
    np.testing.assert_allclose(s, s_ref, atol=ATOL, rtol=0)
    # Non-negative and descending, as numpy.
    self.assertTrue(np.all(s >= 0))
    self.assertTrue(np.all(s[..., 0] >= s[..., 1]))
    eye = np.broadcast_to(np.eye(2), a.shape)
    np.testing.assert_allclose(np.swapaxes(u, -1, -2) @ u, eye, atol=ATOL,
                               rtol=0)
    np.testing.assert_allclose(np.swapaxes(v, -1, -2) @ v, eye, atol=ATOL,
                               rtol=0)
    recon = u @ (s[..., :, None] * np.swapaxes(v, -1, -2))
    np.testing.assert_allclose(recon, a, atol=ATOL, rtol=0)
    # U is a rotation; the sign of det(A) goes into V.
    np.testing.assert_allclose(np.linalg.det(u), 1.0, atol=ATOL, rtol=0)

  def test_random_matrices(self):
    rng = np.random.default_rng(0)
    self._check(rng.normal(size=(1000, 2, 2)))

  def test_random_deformation_gradients(self):
    rng = np.random.default_rng(1)
    self._check(np.eye(2) + 0.1 * rng.normal(size=(1000, 2, 2)))

  @parameterized.named_parameters(*_degenerate().items())
  def test_degenerate(self, a):
    self._check(a)

  def test_batched_leading_dims(self):
    rng = np.random.default_rng(2)
    a = rng.normal(size=(3, 4, 2, 2)).astype(np.float32)
    u, s, v = linalg.svd2x2(jnp.asarray(a))
    self.assertEqual(u.shape, (3, 4, 2, 2))
    self.assertEqual(s.shape, (3, 4, 2))
    self.assertEqual(v.shape, (3, 4, 2, 2))
    self._check(a)


if __name__ == "__main__":
  absltest.main()
