"""Where to put an obstacle: optimise its placement by gradients through the
GNS or the MPM, verify it with the MPM, and compare with the brute-force
sweep a user would otherwise run (``python -m experiments.inverse_design``).

``run(settings, out_dir)`` writes:

- ``history.csv``: the optimiser's iterations (placement, objective, gradient,
  seconds);
- ``sweep.csv``: the objective against x by MPM and GNS forward rollouts;
- ``summary.json`` and ``report.md``: the MPM's verdict on the start and the
  optimum, and time and objective of the optimiser against the sweep;
- ``objective_vs_x.png``: the sweeps' smooth objective against x, with the
  optimiser's path.

The settings every design study shares are written here once, in groups
that the other studies' ``Settings`` inherit: ``Objective`` (what to
minimise), ``Search`` (rollout length, Adam's step, the sweep),
``Smoothing`` and ``Common`` (the one-obstacle problem).
"""

import dataclasses
import os
from typing import Any

import numpy as np
import tqdm

import mpm
from experiments import figures
from experiments.studies import settings
from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from gnsjax.design import scenes
from gnsjax.design import smoothing
from mpm import budget
from mpm import io as mpm_io
from mpm import sampler
from mpm import scene as scene_lib

SIMULATORS = ("gns", "mpm")
METHODS = ("adam", "adam_smoothed")


def _log(line: str) -> None:
  tqdm.tqdm.write(line)


def _joined(values) -> str:
  return ",".join(f"{v:g}" for v in values)


# ------------------------------------------------------- settings groups ---


@dataclasses.dataclass(frozen=True)
class Objective(settings.Base):
  """What to minimise (``gnsjax.design.objectives``)."""
  objective: str = settings.field("passed_fraction", "What to minimise.",
                                  choices=objectives.NAMES)
  # Lines within the paper's box (scene_lib.Domain), as the sand can reach.
  x_protect: float = settings.field(
      0.4, "passed_fraction: the protected line (m).", lower=0,
      upper=scene_lib.Domain.width)
  target_x: float = settings.field(
      0.6, "centroid: the target deposit centroid x (m).", lower=0,
      upper=scene_lib.Domain.width)
  temperature: float | None = settings.field(
      None, "Temperature (m) of the smooth surrogate (default: the "
      "objective's own).", lower=0, strict=True, upper=1)

  def make_objective(self) -> objectives.Objective:
    return objectives.make(self.objective, x_protect=self.x_protect,
                           target_x=self.target_x,
                           temperature=self.temperature)


@dataclasses.dataclass(frozen=True)
class Search(settings.Base):
  """The rollouts searched over, Adam's step and the sweep."""
  num_frames: int = settings.field(600, "Frames per rollout.", lower=2)
  learning_rate: float = settings.field(
      0.05, "Adam step size (m; for --problem=calibrate, a fraction of each "
      "parameter's range).", lower=0, strict=True, upper=1)
  sweep_points: int = settings.field(
      9, "MPM sweep placements (per parameter with --method=sweep).",
      lower=2)

  def simulations(self) -> list[budget.Planned]:
    """One rollout of the paper's heap per design (its MPM's size)."""
    return [budget.Planned(scenes.one_obstacle(num_frames=self.num_frames),
                           names=FRAMES_ONLY)]


# What the design studies let a user size: the frames (the heap is fixed).
FRAMES_ONLY = {"num_frames": "--num_frames", "spacing": None, "dx": None,
               "scenes": None}


@dataclasses.dataclass(frozen=True)
class Smoothing(settings.Base):
  """Gradients of the objective smoothed in the design
  (``gnsjax.design.smoothing``)."""
  sigma: float = settings.field(
      0.05, "Smoothing scale (m) of the smoothed gradients "
      "(--method=adam_smoothed).", lower=0, strict=True, upper=1)
  num_samples: int = settings.field(
      16, "Perturbed designs per smoothed gradient (even).", lower=2)

  def check_samples(self) -> None:
    """The smoothed gradients draw antithetic pairs."""
    if self.num_samples % 2:
      raise settings.InputError(
          f"--num_samples={self.num_samples}; allowed: an even number >= 2 "
          "(antithetic pairs)")


@dataclasses.dataclass(frozen=True)
class Common(Search, Objective, Smoothing):
  """One obstacle on the paper's heap (``gnsjax.design.scenes``), or the
  first obstacle of a scene file, and how it is searched."""
  scene: str | None = settings.field(
      None, "Scene JSON whose first obstacle is designed (default: the small "
      "config's heap of 250 particles with --shape at --x0).")
  shape: str = settings.field("semicircle", "Obstacle shape (without "
                              "--scene).", choices=tuple(
                                  scene_lib.OBSTACLE_SHAPES))
  size: tuple[float, ...] = settings.field(
      (0.04,), "Obstacle size (m): radius, or width/base,height.")
  x0: float = settings.field(
      1.0, "Starting obstacle x (m), in [%g, %g]." % placement_lib.X_RANGE)
  optimise_size: bool = settings.field(
      False, "Optimise the obstacle's size too (Table 1 ranges).")

  def builds_obstacle(self) -> bool:
    """Whether the study builds its one-obstacle scene (checks --x0 and
    --size)."""
    return self.scene is None

  def validate(self):
    super().validate()
    if not self.builds_obstacle():
      return
    lo, hi = placement_lib.X_RANGE
    if not lo <= self.x0 <= hi:
      raise settings.InputError(f"--x0={self.x0:g}; allowed: [{lo:g}, "
                                f"{hi:g}] m")
    keys = scene_lib.OBSTACLE_SHAPES[self.shape]
    ranges = sampler.SIZE_RANGES[self.shape]
    # Optimised sizes stay in Table 1's ranges; a fixed one need only fit.
    if self.optimise_size:
      ok = all(ranges[k][0] <= s <= ranges[k][1]
               for k, s in zip(keys, self.size))
      allowed = ", ".join(f"{k} in [{ranges[k][0]:g}, {ranges[k][1]:g}]"
                          for k in keys) + " m (--optimise_size)"
    else:
      ok = all(s > 0 for s in self.size)
      allowed = "positive lengths in m"
    if len(self.size) != len(keys) or not ok:
      raise settings.InputError(
          f"--size={_joined(self.size)}: a {self.shape} needs {list(keys)}; "
          f"allowed: {allowed}")

  def design_scene(self) -> mpm.Scene:
    """The scene whose first obstacle is designed: the file ``scene`` (its
    obstacle's x checked against the design range), or the heap with
    ``shape`` of ``size`` at ``x0``.

    Raises:
      InputError: naming --scene.
    """
    if self.scene is None:
      return scenes.one_obstacle(self.shape, self.size, self.x0,
                                 self.num_frames)
    scene = mpm.Scene.load(self.scene)
    if not scene.obstacles:
      raise settings.InputError(f"--scene={self.scene}: no obstacle to "
                                "design; allowed: a scene with obstacles")
    x, (lo, hi) = scene.obstacles[0].x, placement_lib.X_RANGE
    if not lo <= x <= hi:
      raise settings.InputError(f"--scene={self.scene}: obstacles[0].x = "
                                f"{x:g}; allowed: [{lo:g}, {hi:g}] m")
    return scene


# ------------------------------------------------------------------ study ---


@dataclasses.dataclass(frozen=True)
class Settings(Common):
  """Projected Adam on one obstacle's placement, verified by the MPM."""
  simulator: str = settings.field(
      "gns", "Whose gradients drive the optimiser.", choices=SIMULATORS)
  workdir: str = settings.field(
      settings.PRETRAINED, "Trained GNS (default: the shipped model); empty: "
      "MPM only.")
  steps: int = settings.field(8, "Gradient evaluations.", lower=1)
  method: str = settings.field(
      "adam", "adam: plain gradients; adam_smoothed: gradients of the "
      "objective smoothed at --sigma.", choices=METHODS, flag=False)
  estimator: str = settings.field(
      "score", "Estimator of the smoothed gradient.",
      choices=smoothing.ESTIMATORS)

  def validate(self):
    super().validate()
    if self.method == "adam_smoothed":
      self.check_samples()
    if self.simulator == "gns" and not self.workdir:
      raise settings.InputError("--simulator=gns needs --workdir (a trained "
                                "model); or use --simulator=mpm")


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Optimises the first obstacle's x (and size, with ``optimise_size``) of
  the scene and checks the result (module docstring).

  Args:
    s: the settings; the obstacle moves within x in [0.5, 1.3] m.
    out_dir: where the files go (created).

  Returns:
    The summary (summary.json).
  """
  scene = s.design_scene()
  objective = s.make_objective()
  placement = placement_lib.Placement(
      scene, free=("x", "size") if s.optimise_size else ("x",))
  sims = {"mpm": rollouts.MPMDriver(rollouts.MPMRollout.create(placement))}
  if s.workdir:
    sims["gns"] = rollouts.gns_driver(placement, s.workdir)
  driver = sims[s.simulator]
  if s.method == "adam_smoothed":
    # The MPM evaluates the perturbed designs as one batch; the GNS's
    # driver (a host-held neighbour list) one at a time.
    driver = smoothing.SmoothedDriver(driver, sigma=s.sigma,
                                      num_samples=s.num_samples,
                                      estimator=s.estimator)

  def log_record(r):
    _log(f"iteration {r['iteration']}: x = {r['x']:.4f} m, "
         f"{objective.name} = {r['objective']:.5g}, d/dx = "
         f"{r['grad_x']:.4g}, {r['seconds']:.1f} s")

  os.makedirs(out_dir, exist_ok=True)  # once the inputs are known good
  start = placement.initial()
  history = optimize.optimise(driver, objective.smooth, start,
                              steps=s.steps, learning_rate=s.learning_rate,
                              log=log_record)
  mpm_io.write_csv(os.path.join(out_dir, "history.csv"), history)
  best = min(history, key=lambda r: r["objective"])

  # The MPM's verdict on the start and on the optimum.
  verdict = {}
  for label, record in (("start", history[0]), ("optimum", best)):
    params = optimize.from_record(record, s.optimise_size)
    positions = sims["mpm"].rollout(params)
    verdict[label] = {"x": record["x"], "plain": objective.plain(positions),
                      "smooth": float(objective.smooth(positions)),
                      **({"size": params["size"].tolist()}
                         if s.optimise_size else {})}
  improved = verdict["optimum"]["plain"] < verdict["start"]["plain"]

  # The brute-force baseline: forward rollouts over the range (warmed up, so
  # seconds exclude compilation).
  xs = np.linspace(*placement.x_range, s.sweep_points)
  rows = {}
  for name, sim in sims.items():
    sim.rollout(start)
    rows[name] = optimize.sweep(sim, objective.plain, objective.smooth,
                                start, xs)
  sweep_rows = [{"x": float(x), **{f"{n}_{k}": rows[n][i][k]
                                    for n in rows for k in ("plain", "smooth",
                                                            "seconds")}}
                for i, x in enumerate(xs)]
  mpm_io.write_csv(os.path.join(out_dir, "sweep.csv"), sweep_rows)
  mpm_best = min(rows["mpm"], key=lambda r: r["plain"])
  summary = {
      "scene": scene.to_dict(), "objective": objective.name,
      "unit": objective.unit, "simulator": s.simulator, "steps": s.steps,
      "method": s.method, **({"sigma": s.sigma,
                              "num_samples": s.num_samples,
                              "estimator": s.estimator}
                             if s.method == "adam_smoothed" else {}),
      "learning_rate": s.learning_rate,
      "optimiser": {
          "best_x": best["x"], "best_objective": best["objective"],
          "seconds": float(sum(r["seconds"] for r in history)),
          "seconds_after_first": float(sum(r["seconds"]
                                           for r in history[1:])),
          "gradient_evaluations": s.steps},
      "mpm_verdict": verdict, "improved_under_mpm": bool(improved),
      "sweep": {
          "points": int(s.sweep_points),
          "mpm_seconds": float(sum(r["seconds"] for r in rows["mpm"])),
          "mpm_best_x": mpm_best["x"], "mpm_best_plain": mpm_best["plain"],
          **({"gns_seconds": float(sum(r["seconds"] for r in rows["gns"]))}
             if "gns" in rows else {})},
  }
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  mpm_io.write_text(os.path.join(out_dir, "report.md"), report(summary))
  figures.objective_vs_x(rows, history, objective.name, s.simulator,
                         os.path.join(out_dir, "objective_vs_x.png"),
                         smoothed=s.method == "adam_smoothed")
  return summary


def report(summary: dict[str, Any]) -> str:
  """report.md: the optimiser, the MPM's verdict and the sweep, in words."""
  o, v, s = summary["optimiser"], summary["mpm_verdict"], summary["sweep"]
  unit = f" {summary['unit']}" if summary["unit"] else ""
  lines = [
      f"# Inverse design: {summary['objective']}", "",
      f"Adam on {summary['simulator'].upper()} gradients"
      + (f" smoothed at sigma = {summary['sigma']:g} m ({summary['estimator']}"
         f", {summary['num_samples']} samples)"
         if summary.get("method") == "adam_smoothed" else "") + ", "
      f"{o['gradient_evaluations']} gradient evaluations in "
      f"{o['seconds']:.1f} s ({o['seconds_after_first']:.1f} s after the "
      f"first, which compiles): best x = {o['best_x']:.4f} m, smooth "
      f"objective {o['best_objective']:.5g}.", "",
      "| MPM re-simulation | x (m) | objective | smooth |", "|---|---|---|---|",
      f"| start | {v['start']['x']:.4f} | {v['start']['plain']:.5g}{unit} | "
      f"{v['start']['smooth']:.5g} |",
      f"| optimum | {v['optimum']['x']:.4f} | {v['optimum']['plain']:.5g}"
      f"{unit} | {v['optimum']['smooth']:.5g} |", "",
      f"Improved under the MPM: **{summary['improved_under_mpm']}**.", "",
      f"Brute-force MPM sweep ({s['points']} placements): "
      f"{s['mpm_seconds']:.1f} s, best x = {s['mpm_best_x']:.4f} m with "
      f"{s['mpm_best_plain']:.5g}{unit}."]
  if "gns_seconds" in s:
    lines.append(f"The same sweep with the GNS: {s['gns_seconds']:.1f} s.")
  return "\n".join(lines) + "\n"
