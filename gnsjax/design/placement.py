"""What inverse design varies: an obstacle of a scene and its free parameters.

A ``Placement`` names the designed obstacle of a scene, its free parameters
(``x``, and optionally ``size``) and their allowed ranges (Table 1 of the
paper). Parameters travel as a dict ``Params``: ``x`` [] (m), the base
centre's horizontal position, and ``size`` [2] (m), the shape's size vector
of ``mpm.geometry.ObstacleParams`` (a semicircle's radius and 0; a
rectangle's width and height; a triangle's base and height).
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from mpm import geometry
from mpm import sampler
from mpm import scene as scene_lib

# The paper's (Table 1) range of obstacle positions along the ramp (m).
X_RANGE = sampler.OBSTACLE_X_RANGE
FREE_PARAMETERS = ("x", "size")

Params = dict[str, jax.Array]


@dataclasses.dataclass(frozen=True)
class Placement:
  """The designed obstacle of a scene and its free parameters (hashable).

  Attributes:
    scene: the scene; obstacle ``index`` is designed, the others stay.
    index: which obstacle.
    free: the parameters optimised: ("x",) or ("x", "size").
    x_range: allowed base positions (m); the paper's [0.5, 1.3] by
      default.
  """
  scene: scene_lib.Scene
  index: int = 0
  free: tuple[str, ...] = ("x",)
  x_range: tuple[float, float] = X_RANGE

  def __post_init__(self):
    n = len(self.scene.obstacles)
    if not 0 <= self.index < n:
      raise scene_lib.InputError(
          f"index = {self.index}: the scene has {n} obstacle(s); allowed: "
          f"0..{n - 1} (add the obstacle to design to the scene)")
    unknown = set(self.free) - set(FREE_PARAMETERS)
    if not self.free or unknown or "x" not in self.free:
      raise scene_lib.InputError(
          f"free = {self.free}: allowed: ('x',) or ('x', 'size')")
    lo, hi = self.x_range
    if not 0 <= lo < hi <= self.scene.domain.width:
      raise scene_lib.InputError(
          f"x_range = {self.x_range}: must lie within the domain "
          f"[0, {self.scene.domain.width:g}] m with x_min < x_max")
    self.check(self.initial())

  @property
  def obstacle(self) -> scene_lib.Obstacle:
    return self.scene.obstacles[self.index]

  @property
  def size_keys(self) -> tuple[str, ...]:
    return scene_lib.OBSTACLE_SHAPES[self.obstacle.shape]

  def size_range(self) -> np.ndarray:
    """[2, 2] (low, high) of the size vector (Table 1; unused entries 0)."""
    ranges = [sampler.SIZE_RANGES[self.obstacle.shape][k]
              for k in self.size_keys]
    ranges += [(0.0, 0.0)] * (2 - len(ranges))
    return np.asarray(ranges, np.float32)

  def initial(self) -> Params:
    """The scene's values of the free parameters."""
    o = geometry.obstacle_params(self.obstacle)
    return {"x": o.x, "size": o.size} if "size" in self.free else {"x": o.x}

  def obstacle_params(self, params: Params) -> geometry.ObstacleParams:
    """The designed obstacle with ``params`` (traced)."""
    o = geometry.obstacle_params(self.obstacle)
    return o.replace(x=jnp.asarray(params["x"], o.x.dtype),
                     size=jnp.asarray(params.get("size", o.size),
                                      o.size.dtype))

  def obstacles(self, params: Params) -> tuple[geometry.ObstacleParams, ...]:
    """All the scene's obstacles, the designed one at ``params``."""
    return tuple(self.obstacle_params(params) if i == self.index else
                 geometry.obstacle_params(o)
                 for i, o in enumerate(self.scene.obstacles))

  def fixed_scene(self) -> scene_lib.Scene:
    """The scene without the designed obstacle (what stays put)."""
    others = tuple(o for i, o in enumerate(self.scene.obstacles)
                   if i != self.index)
    return dataclasses.replace(self.scene, obstacles=others)

  def project(self, params: Params) -> Params:
    """``params`` clipped onto the allowed ranges."""
    out = {"x": jnp.clip(params["x"], *self.x_range)}
    if "size" in params:
      r = self.size_range()
      out["size"] = jnp.clip(params["size"], r[:, 0], r[:, 1])
    return out

  def scene_at(self, params: Params) -> scene_lib.Scene:
    """The scene with the obstacle at ``params`` (validated: off the ramp,
    outside the domain or overlapping another obstacle raise InputError)."""
    self.check(params)
    d = self.scene.to_dict()
    o = dict(d["obstacles"][self.index], x=float(params["x"]))
    if "size" in params:
      o.update({k: float(v) for k, v in zip(self.size_keys, params["size"])})
    d["obstacles"][self.index] = o
    return scene_lib.Scene.from_dict(d)

  def check(self, params: Params) -> None:
    """Raises InputError (a ValueError) when ``params`` lie outside the
    allowed ranges."""
    x = float(params["x"])
    lo, hi = self.x_range
    if not lo <= x <= hi:
      raise scene_lib.InputError(
          f"obstacle x = {x:g} m is outside the allowed range "
          f"[{lo:g}, {hi:g}] m")
    if "size" in params:
      r = self.size_range()
      size = np.asarray(params["size"], np.float32)
      if np.any(size < r[:, 0] - 1e-7) or np.any(size > r[:, 1] + 1e-7):
        raise scene_lib.InputError(
            f"obstacle size {dict(zip(self.size_keys, size.tolist()))} is "
            f"outside the allowed ranges "
            f"{dict(zip(self.size_keys, r.tolist()))} m")


def with_obstacle(scene: scene_lib.Scene, shape: str, x: float,
                  **sizes: float) -> scene_lib.Scene:
  """``scene`` plus an obstacle (validated; a clear error if off the ramp)."""
  d = scene.to_dict()
  d["obstacles"] = list(d["obstacles"]) + [{"shape": shape, "x": x, **sizes}]
  return scene_lib.Scene.from_dict(d)
