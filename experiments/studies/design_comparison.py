"""Inverse design against the baselines at equal wall time, on the MPM.

``compare(...)`` runs each method on one placement problem under the same
budget (wall time and/or evaluations), every design judged by the MPM:

- ``adam``: projected Adam on the plain pathwise gradient of the smooth
  objective (``optimize.optimise``);
- ``adam_smoothed``: projected Adam on the score-function gradient of the
  objective smoothed at ``sigma`` (``smoothing.SmoothedDriver``);
- ``cmaes``, ``random``, ``sweep``: ``baselines``, batched (one vmapped MPM
  program per batch of designs).

Each method's programs are compiled and run once before its clock starts
(``warmup_s``, reported apart), so the budget is spent on the search. The
value of every design is the plain objective of its MPM rollout (for Adam:
the rollout at the iterate, which its gradient evaluation returns), so the
traces compare like with like; the best design of each method is
re-simulated on its own (``MPMDriver.rollout``) as the verification.

Writes to ``out_dir``: ``trace.csv`` (every evaluation of every method:
seconds, value, best so far, the design), ``summary.json``, ``report.md``
(the table) and ``objective_vs_time.png`` (best MPM objective so far
against wall time per method).
"""

import os
import time
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

import mpm
from gnsjax.design import baselines
from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from gnsjax.design import smoothing
from mpm import io as mpm_io

METHODS = ("adam", "adam_smoothed", "cmaes", "random", "sweep")
# The placement problems of issue 14 (calibration: ``calibration.study``).
PROBLEMS = ("placement", "two_obstacles", "baffles")
# A baffle: a small rectangle (m), within Table 1's rectangle sizes.
BAFFLE_SIZE = (0.02, 0.04)


def step_scale(placement: placement_lib.AnyPlacement,
               params: placement_lib.Params) -> placement_lib.Params:
  """Per-entry scale of Adam's steps and of the smoothing: 1 for positions,
  (size range) / (x range) for sizes, so a step moves each parameter the
  same fraction of its range (unused size entries get that of the first)."""
  width = placement.x_range[1] - placement.x_range[0]
  out = {"x": jnp.ones_like(params["x"])}
  if "size" in params:
    r = np.asarray(placement.size_range(), np.float32)
    span = r[..., 1] - r[..., 0]
    span = np.where(span > 0, span, span[..., :1])     # unused entries
    out["size"] = jnp.asarray(span / width, params["size"].dtype)
  return out


def _adam_trace(history: list[dict]) -> list[dict]:
  """Adam's records as a trace: the seconds at each iteration's end."""
  trace, best, elapsed = [], np.inf, 0.0
  for r in history:
    elapsed += r["seconds"]
    best = min(best, r["plain"])
    trace.append({"evaluation": r["iteration"], "seconds": elapsed,
                  "vector": r["vector"], "value": r["plain"], "best": best,
                  "smooth": r["objective"]})
  return trace


def run_method(method: str, placement: placement_lib.AnyPlacement,
               objective: objectives.Objective, budget: baselines.Budget, *,
               num_frames: int | None = None, learning_rate: float = 0.05,
               sigma: float = 0.05, num_samples: int = 16,
               batch_size: int = 8, sweep_points: int = 3, seed: int = 0,
               sim: rollouts.MPMRollout | None = None,
               log: Callable[[str], None] = print) -> dict[str, Any]:
  """One method under ``budget``: its trace and its warm-up seconds.

  Args:
    method: one of ``METHODS``.
    placement: the problem.
    objective: Adam follows ``smooth``; every design is judged by ``plain``.
    budget: seconds and/or evaluations (for Adam: gradient evaluations).
    num_frames: of the rollouts (default the scene's).
    learning_rate: Adam's step (m) on positions; sizes take the same
      fraction of their range (``step_scale``).
    sigma: smoothing scale (m) of ``adam_smoothed`` on positions, scaled
      like the steps on sizes; num_samples: its perturbed designs.
    batch_size: designs per MPM program of the baselines (CMA-ES's
      population).
    sweep_points: grid values per parameter of ``sweep``.
    seed: of the baselines' and the smoothing's random numbers.
    sim: the MPM rollout (built if None).
  """
  if method not in METHODS:
    raise ValueError(f"method: unknown {method!r}; allowed: {list(METHODS)}")
  budget.check()
  sim = sim or rollouts.MPMRollout.create(placement, num_frames)
  start = placement.initial()
  low, high = placement.bounds()
  if method in ("adam", "adam_smoothed"):
    driver = rollouts.MPMDriver(sim)
    if method == "adam_smoothed":
      scale = step_scale(placement, start)
      driver = smoothing.SmoothedDriver(
          driver, sigma=jax.tree.map(lambda c: sigma * c, scale),
          num_samples=num_samples, estimator="score", seed=seed)
    t = time.perf_counter()
    driver.value_and_grad(objective.smooth, start)          # compiles
    warmup = time.perf_counter() - t

    def log_record(r):
      log(f"{method} iteration {r['iteration']}: {objective.name} = "
          f"{r['plain']:.5g} (smooth {r['objective']:.5g}), "
          f"{r['seconds']:.1f} s")

    history = optimize.optimise(
        driver, objective.smooth, start,
        steps=budget.evaluations or np.iinfo(np.int32).max,
        learning_rate=learning_rate, log=log_record,
        max_seconds=budget.seconds, plain=objective.plain,
        step_scale=step_scale(placement, start))
    # The design of each record, as a vector (records hold flat floats).
    for r in history:
      r["vector"] = placement.to_vector(_record_params(r, start)).tolist()
    trace = _adam_trace(history)
  else:
    fn = baselines.MPMBatchObjective(sim, objective.plain, batch_size)
    t = time.perf_counter()
    fn(placement.to_vector(start)[None])                    # compiles
    warmup = time.perf_counter() - t
    trace = baselines.run(method, fn, low, high, placement.to_vector(start),
                          budget=budget, batch_size=batch_size, seed=seed,
                          points=sweep_points, project=fn.project)
  best = min(trace, key=lambda r: r["value"])
  log(f"{method}: {len(trace)} evaluations, best {objective.name} = "
      f"{best['value']:.5g} at {best['seconds']:.1f} s")
  return {"method": method, "trace": trace, "warmup_s": warmup}


def _record_params(record: dict, like: placement_lib.Params
                   ) -> placement_lib.Params:
  """The placement of an ``optimise`` record (``optimize.as_floats``'s
  inverse for any shape of parameters)."""
  out = {}
  for k, v in like.items():
    v = np.asarray(v)
    if v.ndim == 0:
      out[k] = np.float32(record[k])
    else:
      out[k] = np.asarray([record[f"{k}{i}"] for i in range(v.size)],
                          np.float32).reshape(v.shape)
  return out


def best_at(trace: Sequence[dict], seconds: float) -> float:
  """The best value reached by ``seconds`` of wall time (inf if none)."""
  values = [r["value"] for r in trace if r["seconds"] <= seconds]
  return min(values) if values else float("inf")


def compare(out_dir: str, placement: placement_lib.AnyPlacement,
            objective: objectives.Objective, methods: Sequence[str],
            budget: baselines.Budget, *, problem: str = "two_obstacles",
            progress: Callable[[Sequence[str]], Any] = iter,
            log: Callable[[str], None] = print, **kwargs) -> dict[str, Any]:
  """Runs ``methods`` on ``placement`` under ``budget`` each, verifies each
  best design with the MPM and writes the files (module docstring).

  Args:
    out_dir: where the files go.
    placement: the problem.
    objective: what to minimise.
    methods: some of ``METHODS``.
    budget: per method.
    problem: its name, for the report.
    progress: wraps the loop over methods (e.g. ``tqdm.tqdm``).
    log: one line per iteration or method.
    **kwargs: of ``run_method``.

  Returns:
    The summary (summary.json).
  """
  unknown = [m for m in methods if m not in METHODS]
  if unknown or not methods:
    raise ValueError(f"methods: {list(methods)}; allowed: some of "
                     f"{list(METHODS)}")
  budget.check()
  sim = rollouts.MPMRollout.create(placement, kwargs.pop("num_frames", None))
  driver = rollouts.MPMDriver(sim)
  os.makedirs(out_dir, exist_ok=True)
  start_value = objective.plain(driver.rollout(placement.initial()))
  runs, rows = [], []
  for method in progress(list(methods)):
    result = run_method(method, placement, objective, budget, sim=sim,
                        log=log, **kwargs)
    best = min(result["trace"], key=lambda r: r["value"])
    params = placement.from_vector(best["vector"])
    placement.check(params)
    verified = objective.plain(driver.rollout(params))
    runs.append({
        "method": method, "evaluations": len(result["trace"]),
        "warmup_s": result["warmup_s"],
        "seconds": result["trace"][-1]["seconds"],
        "best": best["value"], "best_at_s": best["seconds"],
        "verified": verified,
        "design": dict(zip(placement.names, best["vector"]))})
    rows += [{"method": method, **{k: r[k] for k in ("evaluation", "seconds",
                                                     "value", "best")},
              **dict(zip(placement.names, r["vector"]))}
             for r in result["trace"]]
  mpm_io.write_csv(os.path.join(out_dir, "trace.csv"), rows)
  winner = min(runs, key=lambda r: (r["verified"], r["best_at_s"]))
  summary = {
      "problem": problem, "scene": placement.scene.to_dict(),
      "parameters": list(placement.names), "objective": objective.name,
      "unit": objective.unit, "budget": budget._asdict(),
      "start": dict(zip(placement.names,
                        placement.to_vector(placement.initial()).tolist())),
      "start_value": start_value, "runs": runs, "winner": winner["method"],
      "settings": {k: v for k, v in kwargs.items()},
      "environment": environment()}
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  with open(os.path.join(out_dir, "report.md"), "w") as f:
    f.write(report(summary))
  plot(rows, summary, os.path.join(out_dir, "objective_vs_time.png"))
  return summary


def environment() -> dict[str, Any]:
  import platform  # pylint: disable=g-import-not-at-top
  return {"machine": platform.machine(), "processor": platform.processor(),
          "cpus": os.cpu_count(), "affinity": sorted(os.sched_getaffinity(0)),
          "load_average": list(os.getloadavg()), "jax": jax.__version__,
          "backend": jax.default_backend()}


def report(summary: dict) -> str:
  """report.md: the table of methods at equal budget, in words."""
  unit = f" {summary['unit']}" if summary["unit"] else ""
  b = summary["budget"]
  limit = " and ".join(x for x in (
      f"{b['seconds']:g} s" if b["seconds"] else "",
      f"{b['evaluations']} evaluations" if b["evaluations"] else "") if x)
  lines = [
      f"# Inverse design, {summary['problem']}: {summary['objective']}", "",
      f"Parameters: {', '.join(summary['parameters'])}; start "
      f"{_fmt(summary['start'])}, MPM objective "
      f"{summary['start_value']:.5g}{unit}. Budget per method: {limit} "
      "(after compilation).", "",
      "| method | evaluations | warm-up (s) | best (MPM) | reached at (s) "
      "| verified (MPM) | design |",
      "|---|---:|---:|---:|---:|---:|---|"]
  for r in summary["runs"]:
    lines.append(
        f"| {r['method']} | {r['evaluations']} | {r['warmup_s']:.1f} | "
        f"{r['best']:.5g} | {r['best_at_s']:.1f} | {r['verified']:.5g} | "
        f"{_fmt(r['design'])} |")
  e = summary["environment"]
  lines += ["", f"Winner (lowest verified objective, then earliest): "
            f"**{summary['winner']}**.", "",
            f"Machine: {e['cpus']} CPUs ({e['machine']}), run on cores "
            f"{e['affinity']}, load average at the end "
            f"{', '.join(f'{x:.2f}' for x in e['load_average'])}; jax "
            f"{e['jax']} on {e['backend']}."]
  return "\n".join(lines) + "\n"


def _fmt(design: dict) -> str:
  return ", ".join(f"{k} = {v:.4g}" for k, v in design.items())


def plot(rows: list[dict], summary: dict, out: str) -> str:
  """Best MPM objective so far against wall time, one line per method."""
  import matplotlib  # pylint: disable=g-import-not-at-top
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top
  fig, ax = plt.subplots(figsize=(6.5, 4))
  for r in summary["runs"]:
    pts = [(q["seconds"], q["best"]) for q in rows
           if q["method"] == r["method"]]
    t, v = zip(*pts)
    ax.step(t, v, where="post", label=f"{r['method']} "
            f"({r['evaluations']} evals)")
  ax.axhline(summary["start_value"], color="gray", ls=":", label="start")
  values = [q["best"] for q in rows] + [summary["start_value"]]
  if min(values) > 0 and max(values) / min(values) > 100:
    ax.set_yscale("log")   # misfits that fall by decades
  ax.set_xlabel("wall time after compilation (s)")
  unit = f" ({summary['unit']})" if summary["unit"] else ""
  ax.set_ylabel(f"best {summary['objective']} so far, MPM{unit}")
  ax.set_title(f"{summary['problem']}: {len(summary['parameters'])} "
               "parameters", fontsize=10)
  ax.legend(fontsize=8)
  fig.tight_layout()
  tmp = f"{out}.tmp-{os.getpid()}.png"
  fig.savefig(tmp, dpi=100)
  plt.close(fig)
  os.replace(tmp, out)
  return out


def baffles_scene(count: int = 5, num_frames: int = 600,
                  spacing: float = 0.01, num_particles: int = 250,
                  x_range: Sequence[float] = placement_lib.X_RANGE
                  ) -> mpm.Scene:
  """The paper's heap with a row of ``count`` baffles (``BAFFLE_SIZE``
  rectangles) evenly spaced over ``x_range``, their centres one reach in
  from its ends."""
  width, height = BAFFLE_SIZE
  reach = float(np.hypot(width / 2, height))
  lo, hi = x_range
  xs = np.linspace(lo + reach, hi - reach, count)
  return mpm.Scene.from_dict({
      "name": f"design_baffles_{count}",
      "granular": {"box": list(mpm.Scene().granular.box), "spacing": spacing,
                   "num_particles": num_particles},
      "num_frames": num_frames,
      "obstacles": [{"shape": "rectangle", "x": float(x), "width": width,
                     "height": height} for x in xs]})


def two_obstacles_scene(x: Sequence[float] = (0.9, 1.1),
                        radius: Sequence[float] = (0.04, 0.04),
                        num_frames: int = 600, spacing: float = 0.01,
                        num_particles: int = 250) -> mpm.Scene:
  """The paper's heap (the small config's spacing) with two semicircles
  (validated: off the ramp or overlapping raise InputError)."""
  scene = mpm.Scene.from_dict({
      "name": "design_two_obstacles",
      "granular": {"box": list(mpm.Scene().granular.box), "spacing": spacing,
                   "num_particles": num_particles},
      "num_frames": num_frames,
      "obstacles": [{"shape": "semicircle", "x": float(a), "radius": float(r)}
                    for a, r in zip(x, radius)]})
  return scene
