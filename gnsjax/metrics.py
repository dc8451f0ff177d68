"""Accuracy metrics of a predicted trajectory against the truth (numpy).

Shapes: T steps, N sand particles. Positions in metres.

- ``positional_mse``: the paper's metric, mean over particles of the squared
  distance between predicted and true positions, per step [T] (m^2).
- ``runout``: the avalanche front, the sand's smallest x (it flows toward
  smaller x), taken as a low quantile so one stray particle does not set it.
- ``deposit_profile``: the top of the sand in bins along x; its error is the
  RMS height difference over the bins where either trajectory has sand.
- ``inside_solids``, ``outside_domain``: the fraction of the sand deeper than
  a tolerance inside the ramp or an obstacle, and outside the domain, per
  step: a flow that leaks through a solid shows here even when its MSE is
  small.
- ``mass_past``: the fraction of the sand past fixed lines across the ramp
  per step, comparable between simulations of different particle counts.
- ``constant_velocity``: the baseline every learned model must beat.
- ``final_speed``: the sand's mean speed over the last steps (m/s): a
  deposit that should rest but jitters in place shows here, not in the MSE.
- ``over_rest_targets``: whether a trajectory's end misses the rest targets
  (end speed over :func:`rest_speed_bound`, kinetic-energy ratio over
  ``REST_KINETIC_ENERGY_RATIO``), as every report counts them.
- ``paired_difference``: how far two models' scores on the same scenes
  differ, against what the draw of the scenes moves.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from mpm import geometry
from mpm import scene as scene_lib

FRONT_QUANTILE = 0.01
# The rest targets (docs/gns.md): learned sand ends no faster than twice the
# MPM's, or 1 cm/s where the MPM's is slower than 5 mm/s, and with at most
# 10 times its kinetic energy.
REST_SPEED_FLOOR = 0.01
REST_KINETIC_ENERGY_RATIO = 10.0


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


def mass_past(positions: np.ndarray, lines: np.ndarray) -> np.ndarray:
  """Fraction [..., L] of the sand past each line x = ``lines`` [L] (m),
  i.e. with a smaller x (the sand flows toward x = 0), of [..., N, 2]."""
  x = np.asarray(positions)[..., 0]
  return np.mean(x[..., None, :] < np.asarray(lines)[:, None], -1)


@jax.jit
def _solid_sdf(ramp, obstacles, p):
  return geometry.solid_sdf(ramp, obstacles, p)


def solid_distance(positions: np.ndarray, scene: scene_lib.Scene) -> np.ndarray:
  """Exact signed distance [...] (m) to the scene's ramp and obstacles at
  positions [..., 2] (negative inside)."""
  p = np.asarray(positions, np.float32)
  phi = _solid_sdf(geometry.ramp_params(scene.ramp),
                   tuple(geometry.obstacle_params(o) for o in scene.obstacles),
                   jnp.asarray(p.reshape(-1, 2)))
  return np.asarray(phi).reshape(p.shape[:-1])


def inside_solids(positions: np.ndarray, scene: scene_lib.Scene,
                  tolerance: float | None = None) -> np.ndarray:
  """Fraction [T] of the sand deeper than ``tolerance`` (default: half the
  particle spacing) inside the ramp or an obstacle, of [T, N, 2]."""
  if tolerance is None:
    tolerance = scene.granular.spacing / 2
  return np.mean(solid_distance(positions, scene) < -tolerance, -1)


def outside_domain(positions: np.ndarray, scene: scene_lib.Scene,
                   tolerance: float | None = None) -> np.ndarray:
  """Fraction [T] of the sand more than ``tolerance`` (default: half the
  particle spacing) outside the domain's box, of [T, N, 2]."""
  if tolerance is None:
    tolerance = scene.granular.spacing / 2
  d = geometry.domain_sdf(scene.domain.width, scene.domain.height,
                          np.asarray(positions))
  return np.mean(np.asarray(d) < -tolerance, -1)


def constant_velocity(positions: np.ndarray, frames: np.ndarray,
                      input_frames: int, frame_stride: int = 1) -> np.ndarray:
  """The constant-velocity baseline [T, N, 2] at stored ``frames`` [T].

  The velocity of the last two input frames, (C - 2) k and (C - 1) k, of a
  trajectory [F, N, 2] carried on unchanged.
  """
  k = frame_stride
  last = (input_frames - 1) * k
  v = (positions[last] - positions[last - k]) / k
  steps = (np.asarray(frames) - last)[:, None, None]
  return positions[last][None] + v[None] * steps


def final_speed(positions: np.ndarray, times: np.ndarray,
                last: int = 5) -> float:
  """Mean particle speed (m/s) over the last ``last`` steps of [T, N, 2]
  positions at ``times`` [T] (s)."""
  if len(times) != len(positions) or len(times) < 2:
    raise ValueError(f"final_speed: {len(positions)} steps and "
                     f"{len(times)} times; need as many, at least 2")
  x, t = positions[-(last + 1):], np.asarray(times, float)[-(last + 1):]
  step = np.linalg.norm(np.diff(x, axis=0), axis=-1)
  return float(np.mean(step / np.diff(t)[:, None]))


def rest_speed_bound(mpm_speed, floor: float = REST_SPEED_FLOOR):
  """The end speed (m/s) learned sand may keep where the MPM's ends at
  ``mpm_speed`` (m/s, a number or an array): max(2 mpm_speed, floor). The
  floor spares a deposit the MPM holds dead still a bound no learned step
  of finite precision can meet."""
  return np.maximum(2 * np.asarray(mpm_speed, float), floor)


def over_rest_targets(final_speed, mpm_final_speed, kinetic_energy_ratio):
  """Which trajectories miss the rest targets: (over_speed, over_energy),
  whether the end speed (m/s, :func:`final_speed`) is over
  :func:`rest_speed_bound` of the MPM's, and whether the kinetic-energy
  ratio (:func:`kinetic_energy_ratio`) is over
  ``REST_KINETIC_ENERGY_RATIO``. Numbers or arrays of one shape in,
  booleans of that shape out."""
  over_speed = (np.asarray(final_speed, float) >
                rest_speed_bound(mpm_final_speed))
  over_energy = (np.asarray(kinetic_energy_ratio, float) >
                 REST_KINETIC_ENERGY_RATIO)
  return over_speed, over_energy


def paired_difference(a, b) -> tuple[float, float]:
  """The mean of a - b over paired samples [S] (two models' scores on the
  same S scenes) and twice its standard error, both in percent of the
  mean of b. A difference within the two standard errors is within what
  another draw of S scenes would move."""
  a, b = np.asarray(a, float), np.asarray(b, float)
  if a.shape != b.shape or a.ndim != 1 or len(a) < 2:
    raise ValueError(f"paired_difference: two [S] arrays with S >= 2; got "
                     f"shapes {a.shape} and {b.shape}")
  d, scale = a - b, 100 / np.mean(b)
  two_se = 2 * np.std(d, ddof=1) / math.sqrt(len(d))
  return float(np.mean(d) * scale), float(two_se * scale)


def front_error_relative(pred: np.ndarray, true: np.ndarray,
                         start: np.ndarray) -> float:
  """|front_pred - front_true| of two frames [N, 2] over the true front's
  runout distance from the first frame ``start`` [N, 2] (a fraction)."""
  travelled = abs(float(runout(true) - runout(start)))
  return abs(float(runout(pred) - runout(true))) / max(travelled, 1e-9)


def specific_kinetic_energy(positions: np.ndarray, times: np.ndarray,
                            last_s: float = 0.25) -> float:
  """Mean kinetic energy per unit mass (J/kg = m^2/s^2) of the sand over
  the last ``last_s`` seconds of [T, N, 2] positions at ``times`` [T] (s):
  the mean over steps and particles of |v|^2 / 2, with v the finite
  difference between stored steps (LagrangeBench's ``e_kin``)."""
  t = np.asarray(times, float)
  if len(t) != len(positions) or len(t) < 2:
    raise ValueError(f"specific_kinetic_energy: {len(positions)} steps and "
                     f"{len(t)} times; need as many, at least 2")
  first = min(int(np.searchsorted(t, t[-1] - last_s)), len(t) - 2)
  x = np.asarray(positions[first:], float)
  v = np.diff(x, axis=0) / np.diff(t[first:])[:, None, None]
  return float(np.mean(0.5 * np.sum(v * v, axis=-1)))


def kinetic_energy_ratio(pred: np.ndarray, true: np.ndarray,
                         pred_times: np.ndarray, true_times: np.ndarray,
                         last_s: float = 0.25, floor: float = 1e-8) -> float:
  """Learned over true sand kinetic energy over the last ``last_s`` seconds
  (:func:`specific_kinetic_energy` of each at its own stored times); 1 is
  as calm as the truth. The truth's energy is floored at ``floor`` J/kg so
  that a deposit at rest in both does not divide by zero."""
  return (specific_kinetic_energy(pred, pred_times, last_s) /
          max(specific_kinetic_energy(true, true_times, last_s), floor))


def rest_time(positions: np.ndarray, times: np.ndarray,
              speed: float = 0.01) -> float:
  """The first time (s) from which the sand's mean speed stays at most
  ``speed`` (m/s) to the end of [T, N, 2] positions at ``times`` [T]; inf
  if it is not at rest at the end."""
  t = np.asarray(times, float)
  v = (np.linalg.norm(np.diff(np.asarray(positions, float), axis=0),
                      axis=-1).mean(axis=1) / np.diff(t))
  moving = np.nonzero(v > speed)[0]
  if not len(moving):
    return float(t[0])
  if moving[-1] == len(v) - 1:
    return math.inf
  return float(t[moving[-1] + 1])


def creep(positions: np.ndarray, times: np.ndarray, since: float) -> float:
  """Mean displacement rate (m/s) of the sand from time ``since`` (s) to
  the end: |x_end - x_since| averaged over particles, over the time
  between. A deposit at rest creeps at 0; jitter in place does not add up
  here, a slow drift does."""
  t = np.asarray(times, float)
  i = int(np.searchsorted(t, since))
  if i >= len(t) - 1:
    return 0.0
  x = np.asarray(positions, float)
  return float(np.mean(np.linalg.norm(x[-1] - x[i], axis=-1)) /
               (t[-1] - t[i]))
