"""Tests for `gnsjax.design.smoothing`: estimators against closed forms."""

import math

from absl.testing import absltest
from absl.testing import parameterized
import jax
import jax.numpy as jnp
import numpy as np

from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from gnsjax.design import smoothing
from tests.gnsjax.design.fixtures import X
from tests.gnsjax.design.fixtures import scene

KEY = jax.random.key(0)
A = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, -0.3], [0.0, -0.3, 3.0]],
             np.float32)
B = np.array([0.1, -0.2, 0.4], np.float32)
PARAMS = {"x": jnp.float32(0.3), "size": jnp.array([-0.5, 0.8], jnp.float32)}


def quadratic(p):
  theta = jnp.concatenate([p["x"][None], p["size"]])
  return 0.5 * theta @ A @ theta + B @ theta


def quadratic_grad(p):
  theta = np.concatenate([[float(p["x"])], np.asarray(p["size"])])
  g = A @ theta + B
  return {"x": g[0], "size": g[1:]}


class SmoothingTest(parameterized.TestCase):

  def test_pathwise_is_exact_on_a_quadratic_with_one_pair(self):
    # grad f(theta + s e) + grad f(theta - s e) = 2 (A theta + b) exactly.
    sigma = {"x": 0.2, "size": 0.05}
    _, grad, _ = smoothing.smoothed_value_and_grad(
        quadratic, PARAMS, KEY, sigma=sigma, num_samples=2)
    want = quadratic_grad(PARAMS)
    np.testing.assert_allclose(grad["x"], want["x"], rtol=1e-5)
    np.testing.assert_allclose(grad["size"], want["size"], rtol=1e-5)

  @parameterized.parameters("pathwise", "score")
  def test_value_and_gradient_of_a_quadratic_in_closed_form(self, estimator):
    # E f(theta + sigma eps) = f(theta) + sigma^2 tr(A) / 2; its gradient is
    # A theta + b for every sigma.
    sigma, n = 0.3, 40000
    value, grad, stderr = jax.jit(
        lambda p, k: smoothing.smoothed_value_and_grad(
            quadratic, p, k, sigma=sigma, num_samples=n,
            estimator=estimator))(PARAMS, KEY)
    want_value = float(quadratic(PARAMS)) + sigma ** 2 * np.trace(A) / 2
    self.assertAlmostEqual(float(value), want_value, delta=0.01)
    want = quadratic_grad(PARAMS)
    got = np.concatenate([[grad["x"]], grad["size"]])
    # The score estimator's error is ~ |g| |eps| / sqrt(n / 2) per entry.
    want = np.concatenate([[want["x"]], want["size"]])
    np.testing.assert_allclose(got, want, atol=0.03)
    # The standard error describes the error: 0 for the pathwise estimator
    # (every pair is exact), the Monte Carlo spread for the score's.
    err = np.concatenate([[stderr["x"]], stderr["size"]])
    if estimator == "pathwise":
      np.testing.assert_allclose(err, 0.0, atol=1e-5)
    else:
      np.testing.assert_array_less(np.abs(got - want), 4 * err)
      np.testing.assert_array_less(err, 0.05)

  @parameterized.parameters("pathwise", "score")
  def test_a_kink_is_smoothed_to_the_gaussian_slope(self, estimator):
    # f = |x|: F_sigma'(x) = erf(x / (sigma sqrt 2)), where f' = sign(x).
    x, sigma = 0.05, 0.1
    _, grad, _ = smoothing.smoothed_value_and_grad(
        lambda p: jnp.abs(p["x"]), {"x": jnp.float32(x)}, KEY, sigma=sigma,
        num_samples=20000, estimator=estimator)
    self.assertAlmostEqual(float(grad["x"]),
                           math.erf(x / (sigma * math.sqrt(2))), delta=0.02)

  def test_a_step_defeats_the_pathwise_estimator_not_the_score(self):
    # f = 1[x > 0]: its derivative is zero almost everywhere, so the pathwise
    # estimate is 0; F_sigma'(x) = N(x / sigma) / sigma, which the score
    # estimator recovers from forward values alone.
    x, sigma = 0.02, 0.05
    step = lambda p: jnp.where(p["x"] > 0, 1.0, 0.0)
    args = ({"x": jnp.float32(x)}, KEY)
    _, pathwise, _ = smoothing.smoothed_value_and_grad(
        step, *args, sigma=sigma, num_samples=20000, estimator="pathwise")
    _, score, _ = smoothing.smoothed_value_and_grad(
        step, *args, sigma=sigma, num_samples=20000, estimator="score")
    self.assertEqual(float(pathwise["x"]), 0.0)
    want = math.exp(-(x / sigma) ** 2 / 2) / math.sqrt(2 * math.pi) / sigma
    self.assertAlmostEqual(float(score["x"]), want, delta=0.05 * want)

  def test_perturbations_are_antithetic_pairs(self):
    eps = np.asarray(smoothing.perturbations(KEY, PARAMS, 6))
    self.assertEqual(eps.shape, (6, 3))
    np.testing.assert_array_equal(eps[1::2], -eps[::2])

  def test_bad_settings_are_refused(self):
    run = lambda **kw: smoothing.smoothed_value_and_grad(
        quadratic, PARAMS, KEY, **{"sigma": 0.1, "num_samples": 4, **kw})
    with self.assertRaisesRegex(ValueError, "num_samples = 3; allowed"):
      run(num_samples=3)
    with self.assertRaisesRegex(ValueError, "estimator = 'adam'; allowed"):
      run(estimator="adam")
    with self.assertRaisesRegex(ValueError, "sigma = 0.0; allowed: > 0"):
      run(sigma=0.0)


class MPMSmoothingTest(absltest.TestCase):
  """Through the MPM: a short rollout where the sand meets the obstacle."""

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.placement = placement_lib.Placement(scene(num_frames=40))
    cls.sim = rollouts.MPMRollout.create(cls.placement)
    # A static method: a plain function stored on the class would bind.
    cls.objective = staticmethod(objectives.make("centroid",
                                                 target_x=1.0).smooth)

  def test_small_sigma_gives_the_pathwise_derivative(self):
    # Before the flow gets rough the plain derivative is reliable
    # (rollouts_test), so smoothing at a scale of 0.1 mm changes it little.
    params = {"x": jnp.float32(X)}
    _, plain, _ = rollouts.MPMDriver(self.sim).value_and_grad(
        self.objective, params)
    _, smooth, _ = smoothing.mpm_smoothed_value_and_grad(
        self.sim, self.objective, params, KEY, sigma=1e-4, num_samples=2)
    np.testing.assert_allclose(float(smooth["x"]), float(plain["x"]),
                               rtol=0.05)

  def test_adam_on_smoothed_gradients(self):
    driver = smoothing.SmoothedDriver(rollouts.MPMDriver(self.sim),
                                      sigma=0.01, num_samples=2)
    history = optimize.optimise(driver, self.objective, {"x": jnp.float32(X)},
                                steps=2, learning_rate=0.01)
    self.assertLen(history, 2)
    lo, hi = self.placement.x_range
    for r in history:
      self.assertTrue(np.isfinite(r["objective"]) and np.isfinite(r["grad_x"]))
      self.assertBetween(r["x"], lo, hi)
    # Each call draws new perturbations (reproducibly from the seed).
    again = smoothing.SmoothedDriver(rollouts.MPMDriver(self.sim),
                                     sigma=0.01, num_samples=2)
    first = again.value_and_grad(self.objective, {"x": jnp.float32(X)})
    self.assertEqual(first[0], history[0]["objective"])

  def test_one_design_at_a_time_equals_the_batch(self):
    # The host loop (what the GNS's driver uses) and the vmapped MPM
    # program: the same designs, the same estimates. (Two samples: the
    # programs of the other tests here.)
    driver = rollouts.MPMDriver(self.sim)
    params = {"x": jnp.float32(X)}
    for estimator in smoothing.ESTIMATORS:
      batched = smoothing.mpm_smoothed_value_and_grad(
          self.sim, self.objective, params, KEY, sigma=0.01, num_samples=2,
          estimator=estimator)
      looped = smoothing.looped_smoothed_value_and_grad(
          driver, self.objective, params, KEY, sigma=0.01, num_samples=2,
          estimator=estimator)
      np.testing.assert_allclose(looped[0], batched[0], rtol=1e-5)
      for got, want in zip(looped[1:], batched[1:]):
        np.testing.assert_allclose(float(got["x"]), float(want["x"]),
                                   rtol=1e-3, atol=1e-6)

  def test_perturbed_designs_stay_in_range_at_the_edge(self):
    # At the top of the allowed range half the perturbed designs would leave
    # it; they are projected onto it, and everything stays finite.
    hi = self.placement.x_range[1]
    value, grad, _ = smoothing.mpm_smoothed_value_and_grad(
        self.sim, self.objective, {"x": jnp.float32(hi)}, KEY, sigma=0.02,
        num_samples=2, estimator="score")
    self.assertTrue(np.isfinite(value) and np.isfinite(float(grad["x"])))
    with self.assertRaisesRegex(ValueError, "outside the allowed range"):
      smoothing.mpm_smoothed_value_and_grad(
          self.sim, self.objective, {"x": jnp.float32(hi + 0.1)}, KEY,
          sigma=0.02)


if __name__ == "__main__":
  absltest.main()
