"""Derivative-free baselines of inverse design, under a budget.

Each baseline minimises a batched function ``fn(vectors [B, P]) -> [B]`` of
the flat design vector (``Placement.to_vector``) inside the box
[low, high] [P], one batch of B designs at a time (one vmapped MPM program,
``MPMBatchObjective``), and stops before a batch once its ``Budget`` is
spent: at most ``evaluations`` designs (the last batch is cut to fit), and
no batch started after ``seconds`` of wall time (the last one may end up to
one batch later). Designs may be repaired by ``project`` (e.g. obstacles
pushed apart) before they are evaluated.

- ``random_search``: uniform samples in the box.
- ``grid_sweep``: the full grid of ``points`` values per parameter, in a
  random order (so that a budget that ends it early leaves an even spread,
  not one corner).
- ``cmaes``: CMA-ES (the ``cma`` package) in the box scaled to [0, 1]^P,
  one generation per batch (population = B), the box handled by ``cma``'s
  own bound transform; a repaired design is told its value plus the
  squared distance of the repair (so the search is drawn back to designs
  that need none).

Each returns the trace: one record per evaluated design, in order, with
the wall time since the start (s), the vector, its value and the best value
so far.
"""

import dataclasses
import itertools
import time
from typing import Callable, NamedTuple

import cma
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts

BatchFn = Callable[[np.ndarray], np.ndarray]
Project = Callable[[np.ndarray], np.ndarray]
METHODS = ("random", "sweep", "cmaes")


class Budget(NamedTuple):
  """When a search stops: after ``evaluations`` designs or ``seconds`` of
  wall time (s), whichever comes first; None: no limit of that kind."""
  evaluations: int | None = None
  seconds: float | None = None

  def check(self) -> None:
    if self.evaluations is None and self.seconds is None:
      raise ValueError("budget: give evaluations or seconds (or both)")
    if self.evaluations is not None and self.evaluations < 1:
      raise ValueError(f"budget: evaluations = {self.evaluations}; allowed: "
                       ">= 1")
    if self.seconds is not None and not self.seconds > 0:
      raise ValueError(f"budget: seconds = {self.seconds}; allowed: > 0")


class _Tracker:
  """Counts evaluations and wall time against a budget; keeps the trace."""

  def __init__(self, fn: BatchFn, budget: Budget, project: Project | None):
    budget.check()
    self.fn, self.budget, self.project = fn, budget, project
    self.start = time.perf_counter()
    self.trace: list[dict] = []
    self.best = np.inf

  def remaining(self) -> int:
    """Designs the next batch may hold (0: stop)."""
    if (self.budget.seconds is not None and
        time.perf_counter() - self.start >= self.budget.seconds):
      return 0
    if self.budget.evaluations is None:
      return np.iinfo(np.int32).max
    return self.budget.evaluations - len(self.trace)

  def evaluate(self, vectors: np.ndarray) -> np.ndarray:
    """Values [B] of the (repaired) designs; records each."""
    vectors = np.asarray(vectors, np.float64)
    if self.project is not None:
      vectors = self.project(vectors)
    values = np.asarray(self.fn(vectors), np.float64)
    seconds = time.perf_counter() - self.start
    for v, f in zip(vectors, values):
      self.best = min(self.best, float(f))
      self.trace.append({"evaluation": len(self.trace), "seconds": seconds,
                         "vector": v.tolist(), "value": float(f),
                         "best": self.best})
    return values


def _check_box(low, high) -> tuple[np.ndarray, np.ndarray]:
  low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
  if low.shape != high.shape or low.ndim != 1 or not np.all(low < high):
    raise ValueError(f"box: low {low} and high {high} must be vectors of one "
                     "length with low < high")
  return low, high


def random_search(fn: BatchFn, low, high, *, budget: Budget,
                  batch_size: int = 8, seed: int = 0,
                  project: Project | None = None) -> list[dict]:
  """Uniform random designs in the box, ``batch_size`` at a time."""
  low, high = _check_box(low, high)
  rng = np.random.default_rng(seed)
  tracker = _Tracker(fn, budget, project)
  while (n := min(batch_size, tracker.remaining())) > 0:
    tracker.evaluate(rng.uniform(low, high, (n, len(low))))
  return tracker.trace


def grid_points(low, high, points: int) -> np.ndarray:
  """The full grid [points^P, P] of ``points`` values per parameter."""
  low, high = _check_box(low, high)
  axes = [np.linspace(lo, hi, points) for lo, hi in zip(low, high)]
  return np.asarray(list(itertools.product(*axes)), np.float64)


def grid_sweep(fn: BatchFn, low, high, *, points: int, budget: Budget,
               batch_size: int = 8, seed: int = 0,
               project: Project | None = None) -> list[dict]:
  """The grid of ``points`` values per parameter, in a random order, until
  it or the budget ends."""
  grid = grid_points(low, high, points)
  grid = grid[np.random.default_rng(seed).permutation(len(grid))]
  tracker = _Tracker(fn, budget, project)
  done = 0
  while done < len(grid) and (n := min(batch_size, tracker.remaining())) > 0:
    tracker.evaluate(grid[done:done + n])
    done += n
  return tracker.trace


def cmaes(fn: BatchFn, low, high, x0, *, budget: Budget,
          batch_size: int = 8, sigma0: float = 0.25, seed: int = 0,
          project: Project | None = None) -> list[dict]:
  """CMA-ES from ``x0`` [P], one generation of ``batch_size`` per batch.

  Args:
    fn, low, high, budget, project: as in the module's description.
    x0: the start (inside the box).
    batch_size: the population (>= 2).
    sigma0: the initial step, as a fraction of the box's side.
    seed: of ``cma``'s sampler.
  """
  low, high = _check_box(low, high)
  if batch_size < 2:
    raise ValueError(f"batch_size = {batch_size}; allowed: >= 2 (CMA-ES's "
                     "population)")
  scale = high - low
  to_box = lambda u: low + scale * np.asarray(u, np.float64)
  es = cma.CMAEvolutionStrategy(
      np.clip((np.asarray(x0, np.float64) - low) / scale, 0, 1), sigma0,
      {"bounds": [0.0, 1.0], "popsize": batch_size, "seed": seed + 1,
       "verbose": -9, "verb_log": 0, "verb_disp": 0,
       "tolfun": 0, "tolx": 0, "tolfunhist": 0, "tolstagnation": 10**9})
  tracker = _Tracker(fn, budget, None)
  while (n := tracker.remaining()) > 0:
    asked = np.asarray(es.ask(), np.float64)
    x = to_box(asked)
    repaired = project(x) if project is not None else x
    values = tracker.evaluate(repaired[:n])
    if n < batch_size:          # the budget cut the generation: no update
      break
    penalty = np.sum(((repaired - x) / scale)**2, axis=1)
    es.tell(list(asked), (values + penalty).tolist())
    if es.stop():
      # Converged to numerical precision: start afresh around the best.
      best = tracker.trace[int(np.argmin([r["value"] for r in
                                          tracker.trace]))]["vector"]
      es = cma.CMAEvolutionStrategy(
          (np.asarray(best) - low) / scale, sigma0 / 4,
          {"bounds": [0.0, 1.0], "popsize": batch_size,
           "seed": seed + 1 + len(tracker.trace), "verbose": -9,
           "verb_log": 0, "verb_disp": 0})
  return tracker.trace


def run(method: str, fn: BatchFn, low, high, x0, *, budget: Budget,
        batch_size: int = 8, seed: int = 0, points: int = 3,
        sigma0: float = 0.25, project: Project | None = None) -> list[dict]:
  """The baseline ``method`` ("random", "sweep" or "cmaes")."""
  if method == "random":
    return random_search(fn, low, high, budget=budget, batch_size=batch_size,
                         seed=seed, project=project)
  if method == "sweep":
    return grid_sweep(fn, low, high, points=points, budget=budget,
                      batch_size=batch_size, seed=seed, project=project)
  if method == "cmaes":
    return cmaes(fn, low, high, x0, budget=budget, batch_size=batch_size,
                 sigma0=sigma0, seed=seed, project=project)
  raise ValueError(f"method: unknown {method!r}; allowed: {list(METHODS)}")


# ------------------------------------------------ the batched MPM objective ---


def pad_batch(vectors, batch_size: int, what: str = "designs"
              ) -> tuple[np.ndarray, int]:
  """``vectors`` [B, P] padded with copies of the last to [batch_size, P]
  (so one compiled program serves every call), and B."""
  vectors = np.asarray(vectors, np.float64)
  b = len(vectors)
  if not 1 <= b <= batch_size:
    raise ValueError(f"{b} {what}; allowed: 1..{batch_size}")
  return np.concatenate([vectors, np.repeat(vectors[-1:], batch_size - b,
                                            0)]), b


@jax.jit
def _mpm_first_last(sim: rollouts.MPMRollout, params):
  def one(p):
    x, finite, max_speed = rollouts.mpm_positions(sim, p, remat=False)
    return x[jnp.asarray([0, -1])], finite, max_speed

  return jax.vmap(one)(params)


@dataclasses.dataclass
class MPMBatchObjective:
  """The plain objective of designs by the MPM, ``batch_size`` designs per
  vmapped program (a shorter batch is padded with its last design, so one
  compiled program serves every call).

  Attributes:
    sim: the MPM rollout of the placement.
    objective: positions [T, N, 2] (host) -> float, called with the first
      and last frames only ([2, N, 2]; every objective of ``objectives``
      reads only those).
    batch_size: designs per program.
  """
  sim: rollouts.MPMRollout
  objective: Callable[[np.ndarray], float]
  batch_size: int = 8

  @property
  def placement(self) -> placement_lib.AnyPlacement:
    return self.sim.placement

  def project(self, vectors: np.ndarray) -> np.ndarray:
    """Vectors [B, P] repaired by the placement's projection."""
    p = self.placement
    return np.stack([p.to_vector(p.project(p.from_vector(v)))
                     for v in vectors])

  def __call__(self, vectors: np.ndarray) -> np.ndarray:
    """Plain objective values [B] of the design vectors [B, P]."""
    padded, b = pad_batch(vectors, self.batch_size)
    params = [self.placement.from_vector(v) for v in padded]
    params = jax.tree.map(lambda *a: jnp.stack(a), *params)
    x, finite, max_speed = _mpm_first_last(self.sim, params)
    x, finite, max_speed = (np.asarray(x), np.asarray(finite),
                            np.asarray(max_speed))
    out = []
    for i in range(b):
      mpm.check_frames(
          f"{self.placement.scene.name} "
          f"({self.placement.describe(self.placement.from_vector(padded[i]))})",
          1, finite[i], max_speed[i], self.sim.max_speed)
      out.append(self.objective(x[i]))
    return np.asarray(out, np.float64)
