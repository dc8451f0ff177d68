"""Calibration: the sand's friction angle and the basal friction from an
observed deposit (``python -m experiments.inverse_design
--problem=calibrate``).

The MPM makes the observed final deposit of the paper's heap (no obstacle,
``gnsjax.design.scenes.heap``) at ``truth``, which no method sees; each
method of ``method`` searches from ``start`` under the same budget for the
two values that reproduce it (``gnsjax.design.calibration``). Each method's
best trial is re-simulated and judged against the truth: friction-angle
error (deg), basal-friction error and the final front's error (a fraction
of the observed runout).

``run(settings, out_dir)`` writes ``trace.csv`` (every evaluation of every
method), ``summary.json``, ``report.md`` and ``objective_vs_time.png`` (the
best misfit so far against wall time per method).
"""

import dataclasses
import os
from typing import Any

import numpy as np
import tqdm

from experiments import figures
from experiments import timing
from experiments.studies import design
from experiments.studies import design_comparison
from experiments.studies import settings
from gnsjax.design import calibration
from gnsjax.design import scenes
from mpm import io as mpm_io


@dataclasses.dataclass(frozen=True)
class Settings(design.Search, design_comparison.Budget):
  """The hidden truth, the start and the methods searching between."""
  truth: tuple[float, ...] = settings.field(
      (33.3, 0.37), "calibrate: the friction angle (deg) and basal friction "
      "that make the observed deposit (hidden from the search).")
  start: tuple[float, ...] = settings.field(
      (25, 0.8), "calibrate: where the search starts (friction angle in "
      "deg, basal friction).")

  def simulations(self):
    return self.batched(super().simulations())

  def validate(self):
    super().validate()
    if any(m not in calibration.METHODS for m in self.method):
      raise settings.InputError(
          f"--method={','.join(self.method)}: allowed for "
          "--problem=calibrate: one or more of "
          f"{', '.join(sorted(calibration.METHODS))}")
    for name in ("truth", "start"):
      values = getattr(self, name)
      if len(values) != 2:
        raise settings.InputError(
            f"--{name}={','.join(f'{v:g}' for v in values)}: allowed: two "
            "numbers, the friction angle (deg) and the basal friction")
      try:
        calibration.check(values)
      except settings.InputError as e:
        raise settings.InputError(f"--{name}: {e}") from None


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Observes the deposit at ``s.truth``, runs each method from ``s.start``
  under the budget and writes the files (module docstring).

  Returns:
    The summary (summary.json).
  """
  truth, start = np.asarray(s.truth), np.asarray(s.start)
  problem = calibration.Calibration.observe(
      scenes.heap("calibrate", s.num_frames), truth,
      batch_size=s.batch_size)
  budget = s.budget()
  os.makedirs(out_dir, exist_ok=True)
  env = timing.environment(False, affinity=sorted(os.sched_getaffinity(0)))
  start_value = float(problem(start[None])[0])
  runs, rows = [], []
  for method in s.method:
    result = calibration.calibrate(
        method, problem, start, budget=budget,
        learning_rate=s.learning_rate, points=s.sweep_points, seed=s.seed)
    best = min(result["trace"], key=lambda r: r["value"])
    theta = np.asarray(best["vector"])
    run_ = {"method": method, "evaluations": len(result["trace"]),
            "warmup_s": result["warmup_s"], "best": best["value"],
            "best_at_s": best["seconds"],
            "design": dict(zip(calibration.NAMES, theta.tolist())),
            "friction_angle_error_deg": abs(theta[0] - truth[0]),
            "basal_friction_error": abs(theta[1] - truth[1]),
            "front_error": problem.front_error(theta)}
    runs.append(run_)
    tqdm.tqdm.write(f"{method}: {_describe(theta)}, misfit "
                    f"{best['value']:.3g}, front error "
                    f"{run_['front_error']:.2%}")
    rows += [{"method": method, **{k: r[k] for k in ("evaluation", "seconds",
                                                     "value", "best")},
              **dict(zip(calibration.NAMES, r["vector"]))}
             for r in result["trace"]]
  timing.end_environment(env)
  summary = {
      "problem": "calibrate", "scene": problem.scene.to_dict(),
      "parameters": list(calibration.NAMES), "objective": "deposit misfit",
      "unit": "", "truth": dict(zip(calibration.NAMES, truth.tolist())),
      "start": dict(zip(calibration.NAMES, start.tolist())),
      "start_value": start_value,
      "start_front_error": problem.front_error(start),
      "budget": budget._asdict(), "runs": runs,
      "settings": {"learning_rate": s.learning_rate,
                   "points": s.sweep_points, "seed": s.seed},
      "environment": env}
  mpm_io.write_csv(os.path.join(out_dir, "trace.csv"), rows)
  mpm_io.write_json(os.path.join(out_dir, "summary.json"), summary)
  mpm_io.write_text(os.path.join(out_dir, "report.md"), report(summary))
  figures.objective_vs_time(rows, summary,
                            os.path.join(out_dir, "objective_vs_time.png"))
  return summary


def _describe(theta) -> str:
  return f"friction angle {theta[0]:.2f} deg, basal friction {theta[1]:.3f}"


def report(summary: dict[str, Any]) -> str:
  """report.md: each method's calibration against the hidden truth."""
  t, s = summary["truth"], summary["start"]
  lines = [
      "# Calibration: friction angle and basal friction from a deposit", "",
      f"Truth (hidden from the search): {_describe(list(t.values()))}. "
      f"Start: {_describe(list(s.values()))} (misfit "
      f"{summary['start_value']:.3g}, front error "
      f"{summary['start_front_error']:.1%}). Budget per method: "
      f"{design_comparison.budget_text(summary['budget'])} (after "
      "compilation).", "",
      "| method | evaluations | warm-up (s) | best misfit | reached at (s) "
      "| friction angle (deg) | basal friction | angle error (deg) | basal "
      "error | front error |",
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
  for r in summary["runs"]:
    d = r["design"]
    lines.append(
        f"| {r['method']} | {r['evaluations']} | {r['warmup_s']:.1f} | "
        f"{r['best']:.3g} | {r['best_at_s']:.1f} | "
        f"{d['friction_angle_deg']:.2f} | {d['basal_friction']:.3f} | "
        f"{r['friction_angle_error_deg']:.2f} | "
        f"{r['basal_friction_error']:.3f} | {r['front_error']:.2%} |")
  lines += ["", "Targets: friction angle within 1 deg, basal friction "
            "within 0.02, final front within 2%.", "",
            design_comparison.machine_text(summary["environment"])]
  return "\n".join(lines) + "\n"
