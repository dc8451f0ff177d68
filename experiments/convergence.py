"""The MPM's answer against its resolution: granular column collapse.

  python -m experiments.convergence --out=DIR [--aspect_ratios=0.5,1,2,4] \
      [--spacings=0.005,0.0025,0.00125] [--cfl=0.4]

The runout of ``experiments.column_collapse`` at each particle spacing (grid
spacing twice it); Richardson extrapolation over the three finest spacings
estimates the converged value when the changes shrink. Writes
``convergence.csv`` and ``convergence.md``.
"""

import math
import os
import time

from absl import flags
import numpy as np
import tqdm

import mpm
from experiments import column_collapse
from experiments import evaluation
from experiments import runtime
from mpm import io as mpm_io

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_ASPECTS = flags.DEFINE_list("aspect_ratios", ["1"],
                             "Column height / width values.")
_SPACINGS = flags.DEFINE_list("spacings", ["0.005", "0.0025", "0.00125"],
                              "Particle spacings (m), coarse to fine.")
_CFL = flags.DEFINE_float("cfl", 0.4, "CFL number of the solver.")
_HEIGHT = flags.DEFINE_float("height", 0.1, "Column height h0 (m).")
_TIME = flags.DEFINE_float("time", 0.8, "Simulated time (s).")

def main(argv):
  del argv
  runtime.writable("out", _OUT.value)
  try:
    aspects = [float(a) for a in _ASPECTS.value]
    spacings = [float(s) for s in _SPACINGS.value]
  except ValueError as e:
    raise mpm.InputError(f"--aspect_ratios/--spacings: {e}; allowed: "
                         "comma-separated numbers") from e
  if any(a <= 0 for a in aspects) or any(s <= 0 for s in spacings):
    raise mpm.InputError("--aspect_ratios and --spacings must be > 0")
  runtime.enable_compilation_cache()
  os.makedirs(_OUT.value, exist_ok=True)
  rows = []
  for aspect in aspects:
    for spacing in tqdm.tqdm(spacings, desc=f"a = {aspect:g}", unit="run"):
      scene = column_collapse.column_scene(aspect, spacing, _HEIGHT.value,
                                           _CFL.value, _TIME.value)
      start = time.perf_counter()
      result = mpm.simulate(scene)
      wall = time.perf_counter() - start
      x = np.asarray(result.positions)
      front, q995 = column_collapse.runouts(x[-1, :, 0],
                                            _HEIGHT.value / aspect)
      rows.append({"aspect_ratio": aspect, "spacing_m": spacing,
                   "dx_m": scene.dx, "particles": x.shape[1],
                   "runout_front": round(front, 4),
                   "runout_q995": round(q995, 4),
                   "still_moving_m": float(np.abs(x[-1] - x[-11]).max()),
                   "wall_time_s": round(wall, 1)})
      evaluation.write_csv(os.path.join(_OUT.value, "convergence.csv"), rows)
  lines = ["| a | spacing (m) | dx (m) | particles | runout (front) | runout "
           "(99.5%) | wall (s) |", "|---" * 7 + "|"]
  for r in rows:
    lines.append(f"| {r['aspect_ratio']:g} | {r['spacing_m']:g} | "
                 f"{r['dx_m']:g} | {r['particles']} | {r['runout_front']} | "
                 f"{r['runout_q995']} | {r['wall_time_s']} |")
  lines.append("")
  for aspect in aspects:
    mine = [r for r in rows if r["aspect_ratio"] == aspect]
    if len(mine) >= 3:
      for key in ("runout_front", "runout_q995"):
        value, order = column_collapse.richardson([r[key] for r in mine])
        lines.append(f"- a = {aspect:g}, {key}: Richardson "
                     + (f"{value:.3f} (order {order:.2f})"
                        if math.isfinite(value) else
                        "undefined: the changes do not shrink"))
  mpm_io.write_text(os.path.join(_OUT.value, "convergence.md"),
                    "\n".join(lines) + "\n")
  print("\n".join(lines))


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
