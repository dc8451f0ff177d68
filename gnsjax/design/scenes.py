"""The scenes of the inverse-design problems: the paper's heap at the small
config's spacing (250 particles, 0.01 m) released onto the ramp, with the
obstacles each problem designs.

- ``heap``: no obstacle (the calibration's scene);
- ``one_obstacle``: one obstacle of a shape and size at x (the placement
  problem, the gradient check, the design benchmark);
- ``two_obstacles``: two semicircles;
- ``baffles``: a row of small rectangles (``BAFFLE_SIZE``).

Every scene is validated (``mpm.Scene.from_dict``): an obstacle off the
ramp or two overlapping raise ``mpm.InputError``.
"""

from typing import Sequence

import numpy as np

import mpm
from gnsjax.design import placement as placement_lib
from mpm import scene as scene_lib

# A baffle: a small rectangle (m), within Table 1's rectangle sizes.
BAFFLE_SIZE = (0.02, 0.04)


def heap(name: str, num_frames: int = 600, spacing: float = 0.01,
         num_particles: int = 250, obstacles: Sequence[dict] = ()
         ) -> mpm.Scene:
  """The paper's heap (its box, ``num_particles`` at ``spacing`` m) with
  ``obstacles`` (scene-file dicts), ``num_frames`` frames."""
  return mpm.Scene.from_dict({
      "name": name,
      "granular": {"box": list(scene_lib.Granular.box), "spacing": spacing,
                   "num_particles": num_particles},
      "num_frames": num_frames,
      **({"obstacles": [dict(o) for o in obstacles]} if obstacles else {})})


def one_obstacle(shape: str = "semicircle",
                 size: Sequence[float] = (0.04,), x0: float = 1.0,
                 num_frames: int = 600, spacing: float = 0.01,
                 num_particles: int = 250) -> mpm.Scene:
  """The heap with one obstacle of ``shape`` at ``x0`` (m); ``size`` (m)
  holds its sizes in ``mpm.scene.OBSTACLE_SHAPES``' order (a radius, or
  width/base and height).

  Raises:
    ValueError: ``size`` does not fit the shape, or the obstacle is off the
      ramp (``mpm.InputError``).
  """
  keys = scene_lib.OBSTACLE_SHAPES[shape]
  if len(size) != len(keys):
    raise ValueError(f"size = {list(size)}: a {shape} needs {len(keys)} "
                     f"value(s), {list(keys)} (m)")
  base = heap(f"design_{shape}", num_frames, spacing, num_particles)
  return placement_lib.with_obstacle(base, shape, x0,
                                     **dict(zip(keys, size)))


def two_obstacles(x: Sequence[float] = (0.9, 1.1),
                  radius: Sequence[float] = (0.04, 0.04),
                  num_frames: int = 600, spacing: float = 0.01,
                  num_particles: int = 250) -> mpm.Scene:
  """The heap with two semicircles at base positions ``x`` (m) of
  ``radius`` (m)."""
  return heap("design_two_obstacles", num_frames, spacing, num_particles,
              [{"shape": "semicircle", "x": float(a), "radius": float(r)}
               for a, r in zip(x, radius)])


def baffles(count: int = 5, num_frames: int = 600, spacing: float = 0.01,
            num_particles: int = 250,
            x_range: Sequence[float] = placement_lib.X_RANGE) -> mpm.Scene:
  """The heap with a row of ``count`` baffles (``BAFFLE_SIZE`` rectangles)
  evenly spaced over ``x_range`` (m), their centres one reach in from its
  ends."""
  width, height = BAFFLE_SIZE
  reach = float(np.hypot(width / 2, height))
  lo, hi = x_range
  xs = np.linspace(lo + reach, hi - reach, count)
  return heap(f"design_baffles_{count}", num_frames, spacing, num_particles,
              [{"shape": "rectangle", "x": float(x), "width": width,
                "height": height} for x in xs])
