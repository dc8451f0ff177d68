"""Random scenes from the paper's Table 1, deterministic from a seed.

Table 1: 700-1000 particles; 0-2 obstacles with base centres at x in
[0.5, 1.3] m; semicircles of radius 0.02-0.05 m; rectangles 0.02-0.06 m wide
and 0.03-0.07 m high. Triangles (test only in the paper, unseen in training)
take the rectangle's ranges for base and height.
"""

from typing import Sequence

import numpy as np

from mpm import scene as scene_lib

PARTICLE_RANGE = (700, 1000)
OBSTACLE_COUNT_RANGE = (0, 2)
OBSTACLE_X_RANGE = (0.5, 1.3)
SIZE_RANGES = {
    "semicircle": {"radius": (0.02, 0.05)},
    "rectangle": {"width": (0.02, 0.06), "height": (0.03, 0.07)},
    "triangle": {"base": (0.02, 0.06), "height": (0.03, 0.07)},
}
TRAIN_SHAPES = ("semicircle", "rectangle")

_MAX_TRIES = 1000


def sample_obstacle(rng: np.random.Generator, shape: str,
                    x: float | None = None) -> dict:
  """One obstacle dict of ``shape`` with Table 1 sizes (and x unless given)."""
  if shape not in SIZE_RANGES:
    raise ValueError(f"shape: unknown {shape!r}; allowed: {list(SIZE_RANGES)}")
  sizes = {k: float(rng.uniform(*r)) for k, r in SIZE_RANGES[shape].items()}
  if x is None:
    x = float(rng.uniform(*OBSTACLE_X_RANGE))
  return {"shape": shape, "x": float(x), **sizes}


def sample_scene(seed: int, *, num_particles: int | None = None,
                 num_obstacles: int | None = None,
                 shapes: Sequence[str] = TRAIN_SHAPES,
                 obstacle_x: Sequence[float] | None = None,
                 spacing: float = scene_lib.Granular.spacing,
                 name: str | None = None, **overrides) -> scene_lib.Scene:
  """Draws a paper scene; every unset choice comes from Table 1.

  Args:
    seed: the scene is a pure function of the seed and the arguments.
    num_particles: fixed particle count, else uniform in 700-1000.
    num_obstacles: fixed count, else uniform in 0-2.
    shapes: shapes to draw obstacles from (add "triangle" for test scenes).
    obstacle_x: fixed base positions (one per obstacle), else uniform in
      [0.5, 1.3] m.
    spacing: particle spacing (m); the grid spacing is twice that.
    name: the scene's name (default "seed_<seed>").
    **overrides: other top-level scene keys (e.g. num_frames=100).

  Returns:
    A validated :class:`mpm.Scene`; obstacles never overlap.
  """
  rng = np.random.default_rng(seed)
  if num_particles is None:
    num_particles = int(rng.integers(PARTICLE_RANGE[0], PARTICLE_RANGE[1] + 1))
  if num_obstacles is None:
    num_obstacles = int(rng.integers(OBSTACLE_COUNT_RANGE[0],
                                     OBSTACLE_COUNT_RANGE[1] + 1))
  if obstacle_x is not None and len(obstacle_x) != num_obstacles:
    raise ValueError(f"obstacle_x: {len(obstacle_x)} positions given for "
                     f"{num_obstacles} obstacles")
  base = {"name": name or f"seed_{seed}",
          "granular": {"box": list(scene_lib.Granular.box),
                       "spacing": spacing,
                       "num_particles": num_particles}, **overrides}
  last_error = None
  for _ in range(_MAX_TRIES):
    obstacles = [
        sample_obstacle(rng, str(rng.choice(list(shapes))),
                        None if obstacle_x is None else obstacle_x[i])
        for i in range(num_obstacles)]
    try:
      return scene_lib.Scene.from_dict({**base, "obstacles": obstacles})
    except ValueError as e:  # overlapping obstacles: draw again
      last_error = e
  raise ValueError(f"sample_scene: no valid scene in {_MAX_TRIES} draws for "
                   f"seed {seed}: {last_error}")
