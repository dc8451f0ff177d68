"""Tests for `gnsjax.metrics` against hand computations."""

from absl.testing import absltest
import numpy as np

from gnsjax import metrics


class MetricsTest(absltest.TestCase):

  def test_positional_mse_by_hand(self):
    true = np.zeros((2, 2, 2))
    pred = np.array([[[3.0, 4.0], [0.0, 0.0]],     # errors 25 and 0
                     [[1.0, 0.0], [0.0, 2.0]]])    # errors 1 and 4
    np.testing.assert_allclose(metrics.positional_mse(pred, true),
                               [12.5, 2.5])
    with self.assertRaisesRegex(ValueError, "shapes differ"):
      metrics.positional_mse(pred, true[:, :1])

  def test_runout_is_the_front(self):
    x = np.linspace(0.5, 1.5, 101)
    frame = np.stack([x, np.zeros_like(x)], -1)[None]
    np.testing.assert_allclose(metrics.runout(frame, 0.0), [0.5])
    np.testing.assert_allclose(metrics.runout(frame, 0.01), [0.51])
    shifted = frame + np.array([-0.2, 0.0])
    np.testing.assert_allclose(metrics.runout_error(shifted, frame), [0.2])

  def test_deposit_profile_and_error(self):
    true = np.array([[0.05, 0.1], [0.05, 0.3], [0.15, 0.2]])
    edges = np.array([0.0, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(metrics.deposit_profile(true, edges),
                               [0.3, 0.2, np.nan])
    self.assertEqual(metrics.deposit_error(true, true, 0.1), 0.0)
    # Bins of 0.1 m from the leftmost sand (0.05): one 0.1 m too high, the
    # other right, so RMS = 0.1 / sqrt(2).
    true = np.array([[0.05, 0.1], [0.05, 0.3], [0.2, 0.2]])
    pred = true + np.array([[0.0, 0.1], [0.0, 0.1], [0.0, 0.0]])
    np.testing.assert_allclose(metrics.deposit_error(pred, true, 0.1),
                               0.1 / np.sqrt(2), atol=1e-12)


if __name__ == "__main__":
  absltest.main()
