"""Granular column collapse, the MPM's convergence benchmark: the scene, the
runouts, the paper scenes' measures and Richardson extrapolation
(``python -m experiments.convergence``).

A column of sand (height h0, width h0 / a for aspect ratio a) against a
frictionless wall collapses on a flat floor (friction 0.7, friction angle 45
deg). The normalised runout (L - L0) / L0 is measured from the furthest
particle (the front), from the 99.5% and 90% quantiles of x (L behind which
that fraction of the sand lies) and from the centre of mass: the front
measures the deposit's thinnest toe, the centre its bulk.
"""

import math
from typing import Sequence

import numpy as np

import mpm
from mpm import dataset

FLOOR = 0.02            # m, the floor's height in the domain
FLOOR_FRICTION = 0.7
FRICTION_ANGLE = 45.0   # deg


def column_scene(aspect: float, spacing: float, height: float = 0.1,
                 cfl: float = 0.4, duration: float = 0.8) -> mpm.Scene:
  """A column of ``height`` (m) and width height / aspect against the left
  wall, on a flat floor with room to run out; grid spacing 2 x spacing."""
  width0 = height / aspect
  width = width0 + max(6.0 * height, 0.3)
  return mpm.Scene.from_dict({
      "name": f"column_a{aspect:g}_s{spacing:g}",
      "domain": {"width": width, "height": height + 0.06},
      "ramp": {"kind": "polyline", "points": [[0.0, FLOOR], [width, FLOOR]]},
      "granular": {"box": [0.0, FLOOR, width0, FLOOR + height],
                   "spacing": spacing, "num_particles": None},
      "material": {"friction_angle_deg": FRICTION_ANGLE},
      "boundary_friction": FLOOR_FRICTION, "wall_friction": 0.0,
      "solver": {"dx": 2 * spacing, "cfl": cfl},
      "num_frames": int(round(duration / 0.0025))})


# Deposit measures, from the toe to the bulk: (name, quantile of the final
# x; None for the centre of mass).
MEASURES = (("runout_front", 1.0), ("runout_q995", 0.995),
            ("runout_q90", 0.9), ("centre", None))


def runouts(final_x: np.ndarray, width0: float) -> dict[str, float]:
  """Normalised runouts of the final x [N] (m) of a column of width
  ``width0`` (m), keyed as ``MEASURES``.

  A quantile q gives (L_q - L0) / L0, L_q the x behind which a fraction q of
  the sand lies (1: the furthest particle, the front); the centre gives
  (X - L0 / 2) / L0, X the mean x, L0 / 2 the column's own.
  """
  out = {}
  for name, q in MEASURES:
    if q is None:
      out[name] = (float(np.mean(final_x)) - width0 / 2) / width0
    else:
      out[name] = (float(np.quantile(final_x, q)) - width0) / width0
  return out


def richardson(values: Sequence[float]) -> tuple[float, float]:
  """(extrapolated value, observed order) from values at spacings h, h/2,
  h/4 (coarse to fine); NaN when the changes do not shrink."""
  a, b, c = values[-3:]
  d1, d2 = b - a, c - b
  if d1 == 0 or d2 / d1 <= 0 or abs(d2) >= abs(d1):
    return float("nan"), float("nan")
  ratio = d1 / d2
  order = math.log2(ratio)
  return c + d2 / (ratio - 1), order


# Paper scenes: (name, quantile of x; None for the mean). The sand runs
# towards x = 0, so its front is a low quantile.
PAPER_MEASURES = (("front_travel_m", 0.0), ("front_q01_travel_m", 0.01),
                  ("front_q10_travel_m", 0.1), ("mean_travel_m", None))


def paper_measures(initial_x: np.ndarray,
                   final_x: np.ndarray) -> dict[str, float]:
  """How far (m) each of ``PAPER_MEASURES`` moved downhill between the first
  and the last frame's x [N] (m): distances travelled, so that relative
  errors do not depend on where the domain's origin lies."""
  def at(x, q):
    return float(np.mean(x) if q is None else np.quantile(x, q))
  return {name: at(initial_x, q) - at(final_x, q)
          for name, q in PAPER_MEASURES}


# Below this observed order an extrapolation is dominated by its last change
# (at order 0.1 the limit lies 13 changes away) and is not reported.
MIN_ORDER = 0.5


def extrapolations(rows: Sequence[dict], group: str, keys: Sequence[str],
                   default_spacing: float = dataset.PAPER_SPACING
                   ) -> list[str]:
  """A line per value of ``rows``' column ``group`` and per ``key``: the
  changes between successive rows (coarse to fine, column ``spacing_m``),
  Richardson extrapolation over the last three, and how far the row at
  ``default_spacing`` (m) and the finest row lie from it (relative)."""
  lines = []
  for value in dict.fromkeys(r[group] for r in rows):
    mine = [r for r in rows if r[group] == value]
    if len(mine) < 3:
      continue
    for key in keys:
      values = [r[key] for r in mine]
      limit, order = richardson(values)
      label = f"{value:g}" if isinstance(value, float) else value
      if not math.isfinite(limit):
        verdict = "Richardson undefined: the changes do not shrink"
      elif order < MIN_ORDER:
        verdict = (f"the changes shrink too slowly (order {order:.2f}) for "
                   "an extrapolation to mean anything")
      else:
        verdict = (f"Richardson {limit:.4g} (order {order:.2f}); the "
                   "default spacing's value is "
                   f"{_off(mine, key, limit, default_spacing)} from it, the "
                   f"finest's {_relative(values[-1], limit):.1%}")
      changes = ", ".join(f"{b - a:+.3g}" for a, b in zip(values, values[1:]))
      lines.append(f"- {group} {label}, {key} (changes {changes}): {verdict}")
  return lines


def _relative(value, limit):
  return abs(value - limit) / max(abs(limit), 1e-12)


def _off(rows, key, limit, default_spacing):
  default = [r for r in rows if r["spacing_m"] == default_spacing]
  if not default:
    return "(not run)"
  return f"{_relative(default[0][key], limit):.1%}"


def markdown_table(rows: Sequence[dict]) -> list[str]:
  """Lines of a markdown table of ``rows`` (dicts with the same keys)."""
  cols = list(rows[0])
  lines = ["| " + " | ".join(cols) + " |", "|---" * len(cols) + "|"]
  for r in rows:
    lines.append("| " + " | ".join(
        f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c])
        for c in cols) + " |")
  return lines
