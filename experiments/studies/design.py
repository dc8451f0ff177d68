"""An inverse-design study: optimise a placement, verify it with the MPM,
compare with the brute-force sweep a user would otherwise run.

``study(...)`` writes to ``out_dir``:

- ``history.csv``: the optimiser's iterations (placement, objective, gradient,
  seconds);
- ``sweep.csv``: the objective against x by MPM and GNS forward rollouts;
- ``summary.json`` and ``report.md``: the MPM's verdict on the start and the
  optimum, and time and objective of the optimiser against the sweep.

It returns them too, for plots (``experiments.figures.objective_vs_x``).
"""

import os
from typing import Any, Callable, NamedTuple

import numpy as np

import mpm
from gnsjax import train
from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from gnsjax.design import smoothing
from mpm import io as mpm_io

SIMULATORS = ("gns", "mpm")
METHODS = ("adam", "adam_smoothed")


class StudyResult(NamedTuple):
  """What ``study`` wrote.

  Attributes:
    summary: the contents of summary.json.
    history: the optimiser's records (history.csv).
    sweep: per simulator ("mpm", and "gns" with a model), the sweep's rows
      (x, plain, smooth, seconds) over x.
  """
  summary: dict[str, Any]
  history: list[dict]
  sweep: dict[str, list[dict]]


def gns_driver(placement: placement_lib.Placement,
               workdir: str) -> rollouts.GNSDriver:
  """The trained learned simulator in ``workdir`` (a run directory or a
  shipped model, latest checkpoint) as a function of ``placement``, started
  from the MPM's first input frames of its scene."""
  run = train.load_run(workdir)
  window = rollouts.mpm_window(placement.scene, run.problem.input_frames,
                               run.problem.frame_stride)
  return rollouts.GNSDriver(
      rollouts.GNSRollout.create(placement, run.model, run.problem, window),
      run.params)


def study(out_dir: str, scene: mpm.Scene, objective: objectives.Objective, *,
          simulator: str = "gns", workdir: str | None = None,
          steps: int = 8, learning_rate: float = 0.05,
          sweep_points: int = 9, optimise_size: bool = False,
          method: str = "adam", sigma: float = 0.05, num_samples: int = 16,
          estimator: str = "score",
          log: Callable[[str], None] = print) -> StudyResult:
  """Optimises the first obstacle's x of ``scene`` and checks the result.

  Args:
    out_dir: where the files go.
    scene: its first obstacle is designed, within x in [0.5, 1.3] m.
    objective: what to minimise.
    simulator: "gns" or "mpm", whose gradients drive the optimiser.
    workdir: the trained GNS (a run directory or a shipped model); needed
      for the GNS curve and for ``simulator="gns"``.
    steps, learning_rate: of projected Adam.
    sweep_points: x values of the brute-force sweep over the range.
    optimise_size: optimise the obstacle's size too (within Table 1's
      ranges); the sweep stays over x at the starting size.
    method: "adam" on plain gradients, or "adam_smoothed" on gradients of
      the objective smoothed at scale ``sigma`` (m; ``smoothing``, with
      ``num_samples`` perturbed designs and ``estimator``).
  """
  if simulator not in SIMULATORS:
    raise ValueError(f"simulator: unknown {simulator!r}; allowed: "
                     f"{list(SIMULATORS)}")
  placement = placement_lib.Placement(
      scene, free=("x", "size") if optimise_size else ("x",))
  sims = {"mpm": rollouts.MPMDriver(rollouts.MPMRollout.create(placement))}
  if workdir is not None:
    sims["gns"] = gns_driver(placement, workdir)
  if simulator not in sims:
    raise ValueError("simulator='gns' needs the trained model's workdir")
  if method not in METHODS:
    raise ValueError(f"method: unknown {method!r}; allowed: {list(METHODS)}")
  driver = sims[simulator]
  if method == "adam_smoothed":
    # The MPM evaluates the perturbed designs as one batch; the GNS's
    # driver (a host-held neighbour list) one at a time.
    driver = smoothing.SmoothedDriver(driver, sigma=sigma,
                                      num_samples=num_samples,
                                      estimator=estimator)

  def log_record(r):
    log(f"iteration {r['iteration']}: x = {r['x']:.4f} m, "
        f"{objective.name} = {r['objective']:.5g}, d/dx = {r['grad_x']:.4g}, "
        f"{r['seconds']:.1f} s")

  os.makedirs(out_dir, exist_ok=True)  # once the inputs are known good
  start = placement.initial()
  history = optimize.optimise(driver, objective.smooth, start,
                              steps=steps, learning_rate=learning_rate,
                              log=log_record)
  mpm_io.write_csv(os.path.join(out_dir, "history.csv"), history)
  best = min(history, key=lambda r: r["objective"])

  # The MPM's verdict on the start and on the optimum.
  verdict = {}
  for label, record in (("start", history[0]), ("optimum", best)):
    params = optimize.from_record(record, optimise_size)
    positions = sims["mpm"].rollout(params)
    verdict[label] = {"x": record["x"], "plain": objective.plain(positions),
                      "smooth": float(objective.smooth(positions)),
                      **({"size": params["size"].tolist()}
                         if optimise_size else {})}
  improved = verdict["optimum"]["plain"] < verdict["start"]["plain"]

  # The brute-force baseline: forward rollouts over the range (warmed up, so
  # seconds exclude compilation).
  xs = np.linspace(*placement.x_range, sweep_points)
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
      "unit": objective.unit, "simulator": simulator, "steps": steps,
      "method": method, **({"sigma": sigma, "num_samples": num_samples,
                            "estimator": estimator}
                           if method == "adam_smoothed" else {}),
      "learning_rate": learning_rate,
      "optimiser": {
          "best_x": best["x"], "best_objective": best["objective"],
          "seconds": float(sum(r["seconds"] for r in history)),
          "seconds_after_first": float(sum(r["seconds"]
                                           for r in history[1:])),
          "gradient_evaluations": steps},
      "mpm_verdict": verdict, "improved_under_mpm": bool(improved),
      "sweep": {
          "points": int(sweep_points),
          "mpm_seconds": float(sum(r["seconds"] for r in rows["mpm"])),
          "mpm_best_x": mpm_best["x"], "mpm_best_plain": mpm_best["plain"],
          **({"gns_seconds": float(sum(r["seconds"] for r in rows["gns"]))}
             if "gns" in rows else {})},
  }
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  with open(os.path.join(out_dir, "report.md"), "w") as f:
    f.write(report(summary))
  return StudyResult(summary, history, rows)


def report(summary: dict) -> str:
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
