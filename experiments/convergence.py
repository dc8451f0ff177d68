"""The MPM's answer against its resolution: granular column collapse and the
paper's scenes.

  python -m experiments.convergence --out=DIR [--aspect_ratios=0.5,1,2,4] \
      [--spacings=0.01,0.005,0.0025,0.00125] [--cfl=0.4] \
      [--paper_scenes=0,3] [--paper_spacings=0.01,0.005,0.0025]

The column of ``experiments.column_collapse`` at each particle spacing (grid
spacing twice it), measured from its toe (the furthest particle) to its bulk
(the centre of mass); then the scenes of the paper's test plan named by
``--paper_scenes`` (indices) at ``--paper_spacings``, measured by how far the
avalanche's front (the smallest x: the sand runs towards x = 0), its 1% and
10% quantiles and its mean x travelled. Richardson extrapolation over the
three finest spacings estimates the converged value where the changes
shrink. Writes
``convergence.csv``, ``convergence_paper.csv``, ``convergence.md``,
``deposits.png`` (the final deposits at every spacing, overlaid) and
``environment.json`` (machine, load, command).
"""

import os
import sys
import time

from absl import flags
import numpy as np
import tqdm

import mpm
from experiments import column_collapse
from experiments import figures
from experiments import pareto
from experiments import runtime
from experiments import timing
from mpm import io as mpm_io

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_ASPECTS = flags.DEFINE_list("aspect_ratios", ["1"],
                             "Column height / width values.")
_SPACINGS = flags.DEFINE_list("spacings", ["0.005", "0.0025", "0.00125"],
                              "Particle spacings (m), coarse to fine.")
_CFL = flags.DEFINE_float("cfl", 0.4, "CFL number of the solver.")
_HEIGHT = flags.DEFINE_float("height", 0.1, "Column height h0 (m).")
_TIME = flags.DEFINE_float("time", 0.8, "Simulated time (s).")
_PAPER = flags.DEFINE_list("paper_scenes", [],
                           "Indices of test-plan scenes to measure too.")
_PAPER_SPACINGS = flags.DEFINE_list(
    "paper_spacings", ["0.01", "0.005", "0.0025"],
    "Particle spacings (m) of the paper scenes, coarse to fine.")


def _numbers(name: str, values: list[str], kind: type) -> list:
  """The comma-separated flag ``name`` as numbers: spacings (float) > 0, or
  test-plan indices (int) >= 0; else an InputError naming the flag."""
  allowed = ("comma-separated indices >= 0 into the paper's test plan"
             if kind is int else "comma-separated numbers > 0")
  try:
    out = [kind(v) for v in values]
  except ValueError:
    out = None
  if out is None or any(v < 0 or (kind is float and v == 0) for v in out):
    raise mpm.InputError(f"--{name}={','.join(values)}; allowed: {allowed}")
  return out


def _simulate(scene: mpm.Scene) -> tuple[np.ndarray, float]:
  """Positions [T, N, 2] of ``scene`` and the seconds the call took."""
  start = time.perf_counter()
  x = np.asarray(mpm.simulate(scene).positions)
  return x, time.perf_counter() - start


def main(argv):
  del argv
  runtime.writable("out", _OUT.value)
  aspects = _numbers("aspect_ratios", _ASPECTS.value, float)
  spacings = _numbers("spacings", _SPACINGS.value, float)
  paper = _numbers("paper_scenes", _PAPER.value, int)
  paper_spacings = _numbers("paper_spacings", _PAPER_SPACINGS.value, float)
  plan = pareto.study_scenes(max(paper) + 1) if paper else []
  runtime.enable_compilation_cache()
  os.makedirs(_OUT.value, exist_ok=True)
  env = timing.environment(quick=False, command=" ".join(
      ["python -m experiments.convergence"] + sys.argv[1:]))
  column_rows, paper_rows = [], []
  # Panel title -> (scene, [(spacing, final positions [N, 2])]).
  deposits = {}

  def save():
    mpm_io.write_csv(os.path.join(_OUT.value, "convergence.csv"),
                         column_rows)
    if paper_rows:
      mpm_io.write_csv(os.path.join(_OUT.value, "convergence_paper.csv"),
                           paper_rows)

  for aspect in aspects:
    for spacing in tqdm.tqdm(spacings, desc=f"a = {aspect:g}", unit="run"):
      scene = column_collapse.column_scene(aspect, spacing, _HEIGHT.value,
                                           _CFL.value, _TIME.value)
      x, wall = _simulate(scene)
      column_rows.append({
          "aspect_ratio": aspect, "spacing_m": spacing, "dx_m": scene.dx,
          "particles": x.shape[1],
          **column_collapse.runouts(x[-1, :, 0], _HEIGHT.value / aspect),
          "still_moving_m": float(np.abs(x[-1] - x[-11]).max()),
          "wall_time_s": round(wall, 1)})
      deposits.setdefault(f"column, a = {aspect:g}", (scene, []))[1].append(
          (spacing, x[-1]))
      save()
  for index in paper:
    for spacing in tqdm.tqdm(paper_spacings, desc=plan[index].name,
                             unit="run"):
      scene = pareto.at_spacing(plan[index], spacing)
      x, wall = _simulate(scene)
      paper_rows.append({"scene": plan[index].name, "spacing_m": spacing,
                         "dx_m": scene.dx, "particles": x.shape[1],
                         **column_collapse.paper_measures(x[0, :, 0],
                                                         x[-1, :, 0]),
                         "wall_time_s": round(wall, 1)})
      deposits.setdefault(plan[index].name, (scene, []))[1].append(
          (spacing, x[-1]))
      save()

  if deposits:
    figures.resolution_deposits(
        [(title, scene, runs) for title, (scene, runs) in deposits.items()],
        os.path.join(_OUT.value, "deposits.png"))
  timing.end_environment(env)
  keys = [name for name, _ in column_collapse.MEASURES]
  lines = [f"`{env['command']}`", "",
           f"Machine: {env['platform']}, {env['cpu_count']} CPUs, jax "
           f"{env['jax_version']} ({env['jax_backend']}); load average "
           f"{env['load_average_start'][0]:.2f} at the start, "
           f"{env['load_average_end'][0]:.2f} at the end; {env['date']}.",
           "", "## Column collapse", ""]
  if column_rows:
    lines += column_collapse.markdown_table(column_rows) + [""]
    lines += column_collapse.extrapolations(column_rows, "aspect_ratio", keys)
  if paper_rows:
    lines += ["", "## Paper scenes", ""]
    lines += column_collapse.markdown_table(paper_rows) + [""]
    lines += column_collapse.extrapolations(
        paper_rows, "scene", [n for n, _ in column_collapse.PAPER_MEASURES])
  mpm_io.write_text(os.path.join(_OUT.value, "convergence.md"),
                    "\n".join(lines) + "\n")
  mpm_io.write_json(os.path.join(_OUT.value, "environment.json"), env)
  print("\n".join(lines))


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
