"""Which gradient predicts the objective's change at a scale sigma?
(``python -m experiments.gradient_check``)

At each obstacle position x of the design study's scene (the small
config's heap, 250 particles, a semicircle of radius 0.04 m), through the
MPM or the learned simulator over the whole rollout, ``check`` compares
with the slope of the objective between x - sigma and x + sigma (two
forward runs, what a sweep at spacing 2 sigma sees):

- the plain pathwise derivative (``jax.grad`` at x);
- the smoothed gradient, pathwise estimator (``smoothing``, n samples);
- the smoothed gradient, score-function estimator (forward runs only).

The finite-difference slope is itself the slope of the objective at scale
sigma (of a box, not a Gaussian, smoothing), so agreement in sign and size
is what a user needs from a descent direction at that scale.

``run(settings, out_dir)`` writes ``rows.csv``, ``summary.json`` and
``report.md`` (docs/inverse_design.md).
"""

import dataclasses
import os
import time
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import tqdm

from experiments.studies import design
from experiments.studies import settings
from gnsjax.design import objectives
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from gnsjax.design import scenes
from gnsjax.design import smoothing
from mpm import budget
from mpm import io as mpm_io

SIMULATORS = ("mpm", "gns")


def check(driver, objective: objectives.Objective, xs: Sequence[float], *,
          sigma: float, num_samples: int, hs: Sequence[float] = (),
          seed: int = 0) -> list[dict]:
  """One row per x: the slope over [x - sigma, x + sigma] of the smooth and
  the plain objective, central differences of the smooth objective at each
  h in ``hs``, and the three gradients (with standard errors and seconds;
  the first of each kind includes compilation).

  Args:
    driver: a ``rollouts.MPMDriver`` or ``rollouts.GNSDriver``; its
      placement moves the scene's first obstacle.
    objective: ``objectives.make(...)``; gradients are of ``smooth``.
    xs: obstacle positions (m), each with x +- sigma (and +- h) in the
      allowed range.
    sigma: the scale (m).
    num_samples: perturbed designs per smoothed gradient (even).
    hs: steps (m) of extra central differences: as h shrinks they tend to
      the derivative where the rollout is continuous, and grow like
      (jump / h) where it jumps.
  """
  lo, hi = driver.placement.x_range
  reach = max([sigma, *hs])
  for x in xs:
    if not (lo <= x - reach and x + reach <= hi):
      raise ValueError(f"x = {x:g} m: x +- sigma = {sigma:g} m must lie in "
                       f"the allowed range [{lo:g}, {hi:g}] m")
  smooth = objective.smooth
  rows = []

  def smooth_at(x):
    return float(smooth(jnp.asarray(driver.rollout({"x": jnp.float32(x)}))))

  for i, x in enumerate(xs):
    params = {"x": jnp.float32(x)}
    row = {"x": float(x), "sigma": sigma, "num_samples": num_samples}
    ends = []
    for end in (x - sigma, x + sigma):
      positions = driver.rollout({"x": jnp.float32(end)})
      ends.append((float(smooth(jnp.asarray(positions))),
                   objective.plain(positions)))
    row["slope_smooth"] = (ends[1][0] - ends[0][0]) / (2 * sigma)
    row["slope_plain"] = (ends[1][1] - ends[0][1]) / (2 * sigma)
    for h in hs:
      row[f"difference_h{h:g}"] = (smooth_at(x + h) - smooth_at(x - h)) / (
          2 * h)
    start = time.perf_counter()
    _, grad, _ = driver.value_and_grad(smooth, params)
    row["pathwise"] = float(grad["x"])
    row["pathwise_s"] = time.perf_counter() - start
    for estimator in smoothing.ESTIMATORS:
      start = time.perf_counter()
      _, grad, stderr = smoothing.driver_smoothed_value_and_grad(
          driver, smooth, params, jax.random.key(seed + i), sigma=sigma,
          num_samples=num_samples, estimator=estimator)
      row[f"smoothed_{estimator}"] = float(grad["x"])
      row[f"smoothed_{estimator}_stderr"] = float(stderr["x"])
      row[f"smoothed_{estimator}_s"] = time.perf_counter() - start
    tqdm.tqdm.write(", ".join(f"{k} {v:.4g}" for k, v in row.items()))
    rows.append(row)
  return rows


def report(rows: Sequence[dict], title: str) -> str:
  """A Markdown table of ``check``'s rows and the sign agreements."""
  hs = [k for k in rows[0] if k.startswith("difference_h")]
  lines = [f"# {title}", "",
           "| x (m) | slope over x +- sigma (smooth / plain) | " +
           "".join(f"differences, h = {k[len('difference_h'):]} m | "
                   for k in hs) +
           "jax.grad | smoothed, pathwise | smoothed, score | seconds (grad "
           "/ pathwise / score) |", "|---|---|" + "---|" * len(hs) +
           "---|---|---|---|"]
  agree = {k: 0 for k in ("pathwise", "smoothed_pathwise", "smoothed_score")}
  for r in rows:
    lines.append(
        f"| {r['x']:.2f} | {r['slope_smooth']:.3g} / {r['slope_plain']:.3g} "
        "| " + "".join(f"{r[k]:.3g} | " for k in hs) +
        f"{r['pathwise']:.3g} | {r['smoothed_pathwise']:.3g} +- "
        f"{r['smoothed_pathwise_stderr']:.2g} | {r['smoothed_score']:.3g} +- "
        f"{r['smoothed_score_stderr']:.2g} | {r['pathwise_s']:.1f} / "
        f"{r['smoothed_pathwise_s']:.1f} / {r['smoothed_score_s']:.1f} |")
    for k in agree:
      agree[k] += int(np.sign(r[k]) == np.sign(r["slope_smooth"]))
  lines += ["", f"sigma = {rows[0]['sigma']:g} m, "
            f"{rows[0]['num_samples']} samples per smoothed gradient "
            "(antithetic pairs; +- one standard error).", "",
            "Sign agrees with the slope of the smooth objective: " +
            ", ".join(f"{k} {v}/{len(rows)}" for k, v in agree.items()) + "."]
  return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ study ---


@dataclasses.dataclass(frozen=True)
class Settings(design.Objective, design.Smoothing):
  """Where, at which scale and through which simulator to check."""
  xs: tuple[float, ...] = settings.field(
      (0.6, 0.8, 1.0, 1.2), "Obstacle positions (m).")
  hs: tuple[float, ...] = settings.field(
      (), "Steps (m) of extra central differences.", lower=0, strict=True,
      allow_empty=True)
  num_frames: int = settings.field(600, "Frames per rollout.", lower=2)
  simulator: str = settings.field("mpm", "Whose gradients are checked.",
                                  choices=SIMULATORS)
  workdir: str = settings.field(
      "experiments/pretrained/small",
      "The trained learned simulator (--simulator=gns).")

  def validate(self):
    super().validate()
    lo, hi = placement_lib.X_RANGE
    for flag, name, reach in ((f"--sigma={self.sigma:g}", "sigma",
                               self.sigma),
                              ("--hs", "h", max(self.hs, default=0.0))):
      bad = [x for x in self.xs if not lo <= x - reach <= x + reach <= hi]
      if bad:
        raise settings.InputError(
            f"--xs: {bad} with {flag}: x +- {name} must lie in [{lo:g}, "
            f"{hi:g}] m")
    self.check_samples()

  def simulations(self) -> list[budget.Planned]:
    """A rollout per x and step; the learned simulator's rollouts keep as
    many frames as the MPM's (sized as the MPM's, an upper bound)."""
    return [budget.Planned(scenes.one_obstacle(num_frames=self.num_frames),
                           count=len(self.xs) * (2 * len(self.hs) + 1),
                           names=design.FRAMES_ONLY)]


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Checks the gradients at each x of ``s.xs`` (module docstring) and
  writes the files.

  Returns:
    The summary (summary.json: the settings, the scene and the rows).
  """
  objective = s.make_objective()
  scene = scenes.one_obstacle(num_frames=s.num_frames)
  placement = placement_lib.Placement(scene)
  driver = (rollouts.MPMDriver(rollouts.MPMRollout.create(placement))
            if s.simulator == "mpm" else
            rollouts.gns_driver(placement, s.workdir))
  rows = check(driver, objective, s.xs, sigma=s.sigma,
               num_samples=s.num_samples, hs=s.hs)
  os.makedirs(out_dir, exist_ok=True)
  mpm_io.write_csv(os.path.join(out_dir, "rows.csv"), rows)
  summary = {
      "scene": scene.to_dict(), "objective": s.objective,
      "x_protect": s.x_protect, "target_x": s.target_x,
      "temperature": s.temperature, "simulator": s.simulator,
      "workdir": s.workdir if s.simulator == "gns" else None, "rows": rows}
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  mpm_io.write_text(os.path.join(out_dir, "report.md"), report(
      rows, f"Gradient check ({s.simulator.upper()}): {s.objective}, "
      f"{scene.name}, {s.num_frames} frames"))
  return summary
