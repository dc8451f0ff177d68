"""Inverse design against the baselines at equal wall time, on the MPM
(``python -m experiments.inverse_design --problem=... --method=a,b,...``).

``run(settings, out_dir)`` runs each method on one placement problem under
the same budget (wall time and/or evaluations), every design judged by the
MPM:

- ``adam``: projected Adam on the plain pathwise gradient of the smooth
  objective (``optimize.optimise``);
- ``adam_smoothed``: projected Adam on the score-function gradient of the
  objective smoothed at ``sigma`` (``smoothing.SmoothedDriver``);
- ``cmaes``, ``random``, ``sweep``: ``baselines``, batched (one vmapped MPM
  program per batch of designs).

The problems (``PROBLEMS``): ``placement`` (one obstacle, the design
study's: x, and its size with ``optimise_size``), ``two_obstacles`` (two
semicircles, x and radius each) and ``baffles`` (a row of small rectangles,
their x); the scenes are ``gnsjax.design.scenes``'.

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

import dataclasses
import os
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import tqdm

from experiments import figures
from experiments import timing
from experiments.studies import design
from experiments.studies import settings
from gnsjax.design import baselines
from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from gnsjax.design import scenes
from gnsjax.design import smoothing
from mpm import budget as mpm_budget
from mpm import io as mpm_io
from mpm import sampler

METHODS = ("adam", "adam_smoothed", "cmaes", "random", "sweep")
# The placement problems of issue 14 (calibration: ``studies.calibration``).
PROBLEMS = ("placement", "two_obstacles", "baffles")
BAFFLES = (2, 8)   # baffles in a row: the range allowed


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
               objective: objectives.Objective, s: "Settings",
               sim: rollouts.MPMRollout | None = None) -> dict[str, Any]:
  """One method under the settings' budget: its trace and its warm-up
  seconds.

  Args:
    method: one of ``METHODS``.
    placement: the problem.
    objective: Adam follows ``smooth``; every design is judged by ``plain``.
    s: the budget (for Adam: gradient evaluations), Adam's step (m) on
      positions (sizes take the same fraction of their range:
      ``step_scale``), the smoothing scale (m) and samples of
      ``adam_smoothed`` (scaled like the steps on sizes), the baselines'
      batch (CMA-ES's population) and ``sweep``'s grid values per
      parameter, the seed of the baselines' and the smoothing's random
      numbers.
    sim: the MPM rollout (built if None).
  """
  if method not in METHODS:
    raise ValueError(f"method: unknown {method!r}; allowed: {list(METHODS)}")
  budget = s.budget()
  budget.check()
  sim = sim or rollouts.MPMRollout.create(placement)
  start = placement.initial()
  low, high = placement.bounds()
  if method in ("adam", "adam_smoothed"):
    driver = rollouts.MPMDriver(sim)
    if method == "adam_smoothed":
      scale = step_scale(placement, start)
      driver = smoothing.SmoothedDriver(
          driver, sigma=jax.tree.map(lambda c: s.sigma * c, scale),
          num_samples=s.num_samples, estimator="score", seed=s.seed)
    t = time.perf_counter()
    driver.value_and_grad(objective.smooth, start)          # compiles
    warmup = time.perf_counter() - t

    def log_record(r):
      _log(f"{method} iteration {r['iteration']}: {objective.name} = "
           f"{r['plain']:.5g} (smooth {r['objective']:.5g}), "
           f"{r['seconds']:.1f} s")

    history = optimize.optimise(
        driver, objective.smooth, start,
        steps=budget.evaluations or np.iinfo(np.int32).max,
        learning_rate=s.learning_rate, log=log_record,
        max_seconds=budget.seconds, plain=objective.plain,
        step_scale=step_scale(placement, start))
    # The design of each record, as a vector (records hold flat floats).
    for r in history:
      r["vector"] = placement.to_vector(_record_params(r, start)).tolist()
    trace = _adam_trace(history)
  else:
    fn = baselines.MPMBatchObjective(sim, objective.plain, s.batch_size)
    t = time.perf_counter()
    fn(placement.to_vector(start)[None])                    # compiles
    warmup = time.perf_counter() - t
    trace = baselines.run(method, fn, low, high, placement.to_vector(start),
                          budget=budget, batch_size=s.batch_size,
                          seed=s.seed, points=s.sweep_points,
                          project=fn.project)
  best = min(trace, key=lambda r: r["value"])
  _log(f"{method}: {len(trace)} evaluations, best {objective.name} = "
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


# --------------------------------------------------------------- settings ---


@dataclasses.dataclass(frozen=True)
class Budget(settings.Base):
  """Methods run one after another, each under the same budget."""
  method: tuple[str, ...] = settings.field(
      ("adam",), "One or more (comma-separated) of: adam (plain gradients), "
      "adam_smoothed (gradients of the objective smoothed at --sigma), "
      "cmaes, random, sweep (baselines, batched MPM).")
  budget_s: float | None = settings.field(
      None, "Wall-time budget (s) per method, after compilation.", lower=0,
      strict=True)
  budget_evals: int | None = settings.field(
      None, "Evaluation budget per method (designs; for Adam, gradient "
      "evaluations).", lower=1)
  batch_size: int = settings.field(
      8, "Designs per batched MPM program of the baselines (CMA-ES's "
      "population).", lower=2)
  seed: int = settings.field(0, "Seed of the baselines and the smoothing.",
                             lower=0)

  def validate(self):
    super().validate()
    unknown = [m for m in self.method if m not in METHODS]
    if unknown or len(set(self.method)) != len(self.method):
      raise settings.InputError(
          f"--method={','.join(self.method)}: allowed: one or more distinct "
          f"of {', '.join(METHODS)}")
    if self.budget_s is None and self.budget_evals is None:
      raise settings.InputError("the comparison of methods needs a budget; "
                                "allowed: --budget_s > 0 and/or "
                                "--budget_evals >= 1")

  def budget(self) -> baselines.Budget:
    return baselines.Budget(self.budget_evals, self.budget_s)

  def batched(self, plan: list[mpm_budget.Planned]
              ) -> list[mpm_budget.Planned]:
    """``plan`` and its runs as the baselines' batches of --batch_size."""
    return plan + [dataclasses.replace(
        p, at_once=self.batch_size,
        names={**(p.names or {}), "scenes": "--batch_size"}) for p in plan]


@dataclasses.dataclass(frozen=True)
class Settings(design.Common, Budget):
  """Every method of ``method`` on one problem, at equal budget."""
  problem: str = settings.field(
      "two_obstacles", "placement: one obstacle (x, and its size with "
      "--optimise_size); two_obstacles: two semicircles, x and radius each "
      "(4 parameters); baffles: a row of --num_baffles small rectangles, "
      "their x.", choices=PROBLEMS, flag=False)
  xs: tuple[float, ...] = settings.field(
      (0.9, 1.1), "two_obstacles: starting base positions (m), in [%g, %g]."
      % placement_lib.X_RANGE)
  radii: tuple[float, ...] = settings.field(
      (0.04, 0.04), "two_obstacles: starting radii (m), in [%g, %g]."
      % sampler.SIZE_RANGES["semicircle"]["radius"])
  num_baffles: int = settings.field(
      5, "baffles: how many, in a row (%d-%d)." % BAFFLES)

  def builds_obstacle(self) -> bool:
    return self.problem == "placement"

  def simulations(self) -> list[mpm_budget.Planned]:
    return self.batched(super().simulations())

  def validate(self):
    super().validate()
    self.check_samples()
    if self.problem == "placement" and self.scene is not None:
      raise settings.InputError("--scene: the comparison of methods builds "
                                "its scene; allowed: --shape, --size, --x0")
    lo, hi = BAFFLES  # checked whichever the problem (no silent misuse)
    if not lo <= self.num_baffles <= hi:
      raise settings.InputError(f"--num_baffles={self.num_baffles}; "
                                f"allowed: {lo}-{hi}")
    if self.problem == "two_obstacles":
      self._check_two_obstacles()

  def _check_two_obstacles(self):
    xs, radii = self.xs, self.radii
    for name, values in (("xs", xs), ("radii", radii)):
      if len(values) != 2:
        raise settings.InputError(f"--{name}={_joined(values)}: allowed: 2 "
                                  "comma-separated numbers (m)")
    lo, hi = placement_lib.X_RANGE
    for k, x in enumerate(xs):
      if not lo <= x <= hi:
        raise settings.InputError(
            f"--xs={_joined(xs)}: obstacle {k} at x = {x:g}; allowed: "
            f"[{lo:g}, {hi:g}] m")
    rlo, rhi = sampler.SIZE_RANGES["semicircle"]["radius"]
    for k, r in enumerate(radii):
      if not rlo <= r <= rhi:
        raise settings.InputError(
            f"--radii={_joined(radii)}: obstacle {k} of radius {r:g}; "
            f"allowed: [{rlo:g}, {rhi:g}] m")
    if abs(xs[1] - xs[0]) < radii[0] + radii[1]:
      raise settings.InputError(
          f"--xs={_joined(xs)} with --radii={_joined(radii)}: the obstacles "
          f"overlap; allowed: base centres at least {radii[0] + radii[1]:g} "
          "m apart")

  def placement(self) -> placement_lib.AnyPlacement:
    """The problem's placement: its scene and free parameters."""
    if self.problem == "two_obstacles":
      return placement_lib.MultiPlacement(
          scenes.two_obstacles(self.xs, self.radii, self.num_frames))
    if self.problem == "baffles":
      return placement_lib.MultiPlacement(
          scenes.baffles(self.num_baffles, self.num_frames),
          indices=tuple(range(self.num_baffles)), free=("x",))
    return placement_lib.Placement(
        self.design_scene(),
        free=("x", "size") if self.optimise_size else ("x",))


def _joined(values) -> str:
  return ",".join(f"{v:g}" for v in values)


def _log(line: str) -> None:
  tqdm.tqdm.write(line)


# ------------------------------------------------------------------ study ---


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Runs each method of ``s.method`` on ``s.problem`` under the budget,
  verifies each best design with the MPM and writes the files (module
  docstring).

  Returns:
    The summary (summary.json).
  """
  return compare(s, s.placement(), s.make_objective(), out_dir)


def compare(s: Settings, placement: placement_lib.AnyPlacement,
            objective: objectives.Objective, out_dir: str) -> dict[str, Any]:
  """``run`` on any placement problem and objective (``s.problem`` names
  it in the files)."""
  sim = rollouts.MPMRollout.create(placement)
  driver = rollouts.MPMDriver(sim)
  os.makedirs(out_dir, exist_ok=True)
  env = timing.environment(False, affinity=sorted(os.sched_getaffinity(0)))
  start_value = objective.plain(driver.rollout(placement.initial()))
  runs, rows = [], []
  for method in tqdm.tqdm(s.method, desc="methods", unit="method"):
    result = run_method(method, placement, objective, s, sim)
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
  timing.end_environment(env)
  mpm_io.write_csv(os.path.join(out_dir, "trace.csv"), rows)
  winner = min(runs, key=lambda r: (r["verified"], r["best_at_s"]))
  summary = {
      "problem": s.problem, "scene": placement.scene.to_dict(),
      "parameters": list(placement.names), "objective": objective.name,
      "unit": objective.unit, "budget": s.budget()._asdict(),
      "start": dict(zip(placement.names,
                        placement.to_vector(placement.initial()).tolist())),
      "start_value": start_value, "runs": runs, "winner": winner["method"],
      "settings": {k: getattr(s, k) for k in (
          "learning_rate", "sigma", "num_samples", "batch_size",
          "sweep_points", "seed")},
      "environment": env}
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  mpm_io.write_text(os.path.join(out_dir, "report.md"), report(summary))
  figures.objective_vs_time(rows, summary,
                            os.path.join(out_dir, "objective_vs_time.png"))
  return summary


def budget_text(budget: dict[str, Any]) -> str:
  """A budget (``summary["budget"]``) in words."""
  return " and ".join(x for x in (
      f"{budget['seconds']:g} s" if budget["seconds"] else "",
      f"{budget['evaluations']} evaluations" if budget["evaluations"] else "")
                      if x)


def machine_text(env: dict[str, Any]) -> str:
  """The machine of a run (``timing.environment``) in one sentence."""
  return (f"Machine: {env['cpu_count']} CPUs ({env['machine']}), run on "
          f"cores {env['affinity']}, load average "
          f"{', '.join(f'{x:.2f}' for x in env['load_average_start'])} at "
          "the start and "
          f"{', '.join(f'{x:.2f}' for x in env['load_average_end'])} at the "
          f"end; jax {env['jax_version']} on {env['jax_backend']}.")


def report(summary: dict[str, Any]) -> str:
  """report.md: the table of methods at equal budget, in words."""
  unit = f" {summary['unit']}" if summary["unit"] else ""
  lines = [
      f"# Inverse design, {summary['problem']}: {summary['objective']}", "",
      f"Parameters: {', '.join(summary['parameters'])}; start "
      f"{_fmt(summary['start'])}, MPM objective "
      f"{summary['start_value']:.5g}{unit}. Budget per method: "
      f"{budget_text(summary['budget'])} (after compilation).", "",
      "| method | evaluations | warm-up (s) | best (MPM) | reached at (s) "
      "| verified (MPM) | design |",
      "|---|---:|---:|---:|---:|---:|---|"]
  for r in summary["runs"]:
    lines.append(
        f"| {r['method']} | {r['evaluations']} | {r['warmup_s']:.1f} | "
        f"{r['best']:.5g} | {r['best_at_s']:.1f} | {r['verified']:.5g} | "
        f"{_fmt(r['design'])} |")
  lines += ["", f"Winner (lowest verified objective, then earliest): "
            f"**{summary['winner']}**.", "",
            machine_text(summary["environment"])]
  return "\n".join(lines) + "\n"


def _fmt(design_: dict) -> str:
  return ", ".join(f"{k} = {v:.4g}" for k, v in design_.items())
