"""Accuracy metrics of a predicted trajectory against the truth (numpy).

Shapes: T steps, N sand particles. Positions in metres.

- ``positional_mse``: the paper's metric, mean over particles of the squared
  distance between predicted and true positions, per step [T] (m^2).
- ``runout``: the avalanche front, the sand's smallest x (it flows toward
  smaller x), taken as a low quantile so one stray particle does not set it.
- ``deposit_profile``: the top of the sand in bins along x; its error is the
  RMS height difference over the bins where either trajectory has sand.
"""

import numpy as np

FRONT_QUANTILE = 0.01


def positional_mse(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
  """Per-step mean squared position error [T] (m^2) of [T, N, 2] arrays."""
  if pred.shape != true.shape:
    raise ValueError(f"positional_mse: shapes differ, {pred.shape} vs "
                     f"{true.shape}")
  return np.mean(np.sum((pred - true)**2, -1), -1)


def runout(positions: np.ndarray, quantile: float = FRONT_QUANTILE):
  """Front position [T] (m): the ``quantile`` of the sand's x per frame."""
  return np.quantile(positions[..., 0], quantile, axis=-1)


def runout_error(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
  """|front_pred - front_true| per step [T] (m)."""
  return np.abs(runout(pred) - runout(true))


def deposit_profile(positions: np.ndarray, edges: np.ndarray) -> np.ndarray:
  """Top of the sand [B] (m) in the x bins ``edges`` [B + 1] of one frame
  [N, 2]; NaN where a bin is empty."""
  index = np.digitize(positions[:, 0], edges) - 1
  top = np.full(len(edges) - 1, np.nan)
  inside = (index >= 0) & (index < len(top))
  np.fmax.at(top, index[inside], positions[inside, 1])
  return top


def deposit_error(pred: np.ndarray, true: np.ndarray,
                  bin_width: float) -> float:
  """RMS difference (m) of the deposit profiles of two final frames [N, 2].

  A bin empty in one profile counts as height of the lowest sand there, so
  sand where there should be none (or none where there should be some) is
  an error too.
  """
  lo = min(pred[:, 0].min(), true[:, 0].min())
  hi = max(pred[:, 0].max(), true[:, 0].max())
  edges = np.arange(lo, hi + bin_width, bin_width)
  a, b = deposit_profile(pred, edges), deposit_profile(true, edges)
  either = ~(np.isnan(a) & np.isnan(b))
  floor = min(pred[:, 1].min(), true[:, 1].min())
  a = np.where(np.isnan(a), floor, a)[either]
  b = np.where(np.isnan(b), floor, b)[either]
  return float(np.sqrt(np.mean((a - b)**2)))
