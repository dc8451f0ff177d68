"""Granular column collapse, the MPM's convergence benchmark: the scene, the
runout and Richardson extrapolation (``python -m experiments.convergence``).

A column of sand (height h0, width h0 / a for aspect ratio a) against a
frictionless wall collapses on a flat floor (friction 0.7, friction angle 45
deg). The normalised runout (L - L0) / L0 is measured from the furthest
particle and from the 99.5% quantile of x (less sensitive to single
particles).
"""

import math
from typing import Sequence

import numpy as np

import mpm

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


def runouts(final_x: np.ndarray, width0: float) -> tuple[float, float]:
  """Normalised runouts (L - L0) / L0 of the furthest particle and of the
  99.5% quantile of the final x [N] (m)."""
  return ((float(np.max(final_x)) - width0) / width0,
          (float(np.quantile(final_x, 0.995)) - width0) / width0)


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
