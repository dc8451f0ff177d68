"""What inverse design varies: obstacles of a scene and their free parameters.

A ``Placement`` names the designed obstacle of a scene, its free parameters
(``x``, and optionally ``size``) and their allowed ranges (Table 1 of the
paper). Parameters travel as a dict ``Params``: ``x`` [] (m), the base
centre's horizontal position, and ``size`` [2] (m), the shape's size vector
of ``mpm.geometry.ObstacleParams`` (a semicircle's radius and 0; a
rectangle's width and height; a triangle's base and height).

A ``MultiPlacement`` designs K obstacles at once: ``x`` [K] and ``size``
[K, 2], the same ranges per obstacle, and obstacles that must not overlap
(base centres at least the sum of their reaches apart, as in a scene file).

Both describe their free parameters as a flat vector too (``names``,
``bounds``, ``to_vector``, ``from_vector``) for the derivative-free
baselines; a vector holds only the parameters that act (a semicircle's
unused second size entry is left out).
"""

import dataclasses
import functools

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
  def names(self) -> tuple[str, ...]:
    """The flat vector's entries: "x", then the size keys if free."""
    return ("x",) + (self.size_keys if "size" in self.free else ())

  def bounds(self) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) [P] of the flat vector (m)."""
    r = [self.x_range] + (list(self.size_range()[:len(self.size_keys)])
                          if "size" in self.free else [])
    r = np.asarray(r, np.float64)
    return r[:, 0], r[:, 1]

  def to_vector(self, params: Params) -> np.ndarray:
    """The free parameters as float64 [P] (host)."""
    v = [float(params["x"])]
    if "size" in self.free:
      v += np.asarray(params["size"], np.float64)[:len(self.size_keys)
                                                  ].tolist()
    return np.asarray(v, np.float64)

  def from_vector(self, vector) -> Params:
    """The placement of a flat vector [P] (the inverse of ``to_vector``)."""
    v = np.asarray(vector, np.float32)
    params = {"x": jnp.float32(v[0])}
    if "size" in self.free:
      size = np.zeros(2, np.float32)
      size[:len(self.size_keys)] = v[1:]
      params["size"] = jnp.asarray(size)
    return params

  def describe(self, params: Params) -> str:
    """The placement in words, for messages."""
    return ", ".join(f"{n} = {v:.4g}" for n, v in
                     zip(self.names, self.to_vector(params)))

  def covering_params(self, step: float) -> list[Params]:
    """Placements whose obstacles together cover everywhere the designed
    obstacle can reach: x every ``step`` (m) at the largest free size."""
    params = self.initial()
    if "size" in params:
      params = dict(params, size=jnp.asarray(self.size_range()[:, 1]))
    lo, hi = self.x_range
    return [dict(params, x=jnp.float32(x))
            for x in np.arange(lo, hi + step, step)]

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


# A margin (m) the projection keeps beyond the touching distance, so that a
# projected float32 placement passes the scene's overlap check.
_SEPARATION_MARGIN = 1e-5


def _reach(shape: str, size: jax.Array) -> jax.Array:
  """``scene_lib.Obstacle.reach`` of a (traced) size vector [2] (m)."""
  if shape == "semicircle":
    return size[0]
  return jnp.sqrt((size[0] / 2)**2 + size[1]**2)


def separate(x: jax.Array, reach: jax.Array, lo: float, hi: float
             ) -> jax.Array:
  """Base positions [K] moved apart so that no two obstacles overlap, inside
  [lo, hi] (traceable).

  Neighbours along x that overlap are pushed apart symmetrically by their
  deficit, then a sweep up from ``lo`` and one down from ``hi`` restore the
  gaps (each centre at least reach_i + reach_j + a margin from the next) and
  the range. Positions that already satisfy both come back unchanged. The
  range must hold them: sum of the gaps <= hi - lo.

  Args:
    x: [K] base centres (m).
    reach: [K] their reaches (m).
    lo, hi: the allowed range (m).
  """
  order = jnp.argsort(x)
  xs, rs = x[order], reach[order]
  gap = rs[:-1] + rs[1:] + _SEPARATION_MARGIN                   # [K - 1]
  k = x.shape[0]
  for i in range(k - 1):                 # symmetric: neither one is favoured
    deficit = jnp.maximum(gap[i] - (xs[i + 1] - xs[i]), 0.0)
    xs = xs.at[i].add(-deficit / 2).at[i + 1].add(deficit / 2)
  xs = xs.at[0].set(jnp.maximum(xs[0], lo))
  for i in range(1, k):
    xs = xs.at[i].set(jnp.maximum(xs[i], xs[i - 1] + gap[i - 1]))
  xs = xs.at[k - 1].set(jnp.minimum(xs[k - 1], hi))
  for i in range(k - 2, -1, -1):
    xs = xs.at[i].set(jnp.minimum(xs[i], xs[i + 1] - gap[i]))
  # Rounding may leave lo - 1 ulp; the margin keeps the gaps after the clip.
  xs = jnp.clip(xs, lo, hi)
  return jnp.zeros_like(x).at[order].set(xs)


@dataclasses.dataclass(frozen=True)
class MultiPlacement:
  """Several designed obstacles of a scene and their free parameters
  (hashable).

  Parameters are ``x`` [K] (m) and, if free, ``size`` [K, 2] (m), entry k
  the obstacle ``indices[k]``; each obstacle has ``Placement``'s ranges
  (x in ``x_range``, sizes in Table 1's ranges of its shape), and no two
  may overlap.

  Attributes:
    scene: the scene; obstacles ``indices`` are designed, the others stay.
    indices: which obstacles (distinct, at least one).
    free: ("x",) or ("x", "size"), for every designed obstacle.
    x_range: allowed base positions (m).
  """
  scene: scene_lib.Scene
  indices: tuple[int, ...] = (0, 1)
  free: tuple[str, ...] = ("x", "size")
  x_range: tuple[float, float] = X_RANGE

  def __post_init__(self):
    n = len(self.scene.obstacles)
    if (not self.indices or len(set(self.indices)) != len(self.indices) or
        not all(0 <= i < n for i in self.indices)):
      raise scene_lib.InputError(
          f"indices = {self.indices}: the scene has {n} obstacle(s); allowed: "
          f"distinct indices in 0..{n - 1} (add the obstacles to design to "
          "the scene)")
    _ = self._singles        # each single placement checks free and range
    lo, hi = self.x_range
    need = sum(2 * self.scene.obstacles[i].reach for i in self.indices)
    if need > hi - lo:
      raise scene_lib.InputError(
          f"x_range = {self.x_range}: too short for {len(self.indices)} "
          f"obstacles of total width {need:.3f} m side by side")

  @functools.cached_property
  def _singles(self) -> tuple[Placement, ...]:
    # Built once on the host: a Placement checks concrete values.
    return tuple(Placement(self.scene, i, self.free, self.x_range)
                 for i in self.indices)

  def _single(self, k: int) -> Placement:
    return self._singles[k]

  @property
  def count(self) -> int:
    return len(self.indices)

  @property
  def shapes(self) -> tuple[str, ...]:
    return tuple(self.scene.obstacles[i].shape for i in self.indices)

  @property
  def names(self) -> tuple[str, ...]:
    """The flat vector's entries, per obstacle k: f"x{k}", then its size
    keys with suffix k if sizes are free."""
    return tuple(f"{n}{k}" for k in range(self.count)
                 for n in self._single(k).names)

  def size_range(self) -> np.ndarray:
    """[K, 2, 2] (low, high) of each size vector (unused entries 0)."""
    return np.stack([self._single(k).size_range() for k in range(self.count)])

  def bounds(self) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) [P] of the flat vector (m)."""
    b = [self._single(k).bounds() for k in range(self.count)]
    return (np.concatenate([lo for lo, _ in b]),
            np.concatenate([hi for _, hi in b]))

  def _split(self, params: Params, k: int) -> Params:
    p = {"x": params["x"][k]}
    if "size" in params:
      p["size"] = params["size"][k]
    return p

  def to_vector(self, params: Params) -> np.ndarray:
    """The free parameters as float64 [P] (host)."""
    params = jax.tree.map(np.asarray, params)
    return np.concatenate([self._single(k).to_vector(self._split(params, k))
                           for k in range(self.count)])

  def from_vector(self, vector) -> Params:
    """The placement of a flat vector [P] (the inverse of ``to_vector``)."""
    v = np.asarray(vector, np.float32)
    parts, start = [], 0
    for k in range(self.count):
      single = self._single(k)
      parts.append(single.from_vector(v[start:start + len(single.names)]))
      start += len(single.names)
    return {key: jnp.stack([p[key] for p in parts]) for key in parts[0]}

  def describe(self, params: Params) -> str:
    """The placement in words, for messages."""
    return ", ".join(f"{n} = {v:.4g}" for n, v in
                     zip(self.names, self.to_vector(params)))

  def initial(self) -> Params:
    """The scene's values of the free parameters."""
    parts = [self._single(k).initial() for k in range(self.count)]
    return {key: jnp.stack([p[key] for p in parts]) for key in parts[0]}

  def obstacles(self, params: Params) -> tuple[geometry.ObstacleParams, ...]:
    """All the scene's obstacles, the designed ones at ``params``."""
    out = [geometry.obstacle_params(o) for o in self.scene.obstacles]
    for k, i in enumerate(self.indices):
      out[i] = self._single(k).obstacle_params(self._split(params, k))
    return tuple(out)

  def fixed_scene(self) -> scene_lib.Scene:
    """The scene without the designed obstacles (what stays put)."""
    others = tuple(o for i, o in enumerate(self.scene.obstacles)
                   if i not in self.indices)
    return dataclasses.replace(self.scene, obstacles=others)

  def project(self, params: Params) -> Params:
    """``params`` clipped onto the allowed ranges, the designed obstacles
    then moved apart along x where they overlap (``separate``;
    traceable)."""
    x = jnp.clip(params["x"], *self.x_range)
    out = {"x": x}
    if "size" in params:
      r = self.size_range()
      out["size"] = jnp.clip(params["size"], r[..., 0], r[..., 1])
      size = out["size"]
    else:
      size = jnp.stack([geometry.obstacle_params(self.scene.obstacles[i]).size
                        for i in self.indices])
    reach = jnp.stack([_reach(s, size[k]) for k, s in enumerate(self.shapes)])
    out["x"] = separate(x, reach, *self.x_range)
    return out

  def scene_at(self, params: Params) -> scene_lib.Scene:
    """The scene with the obstacles at ``params`` (validated)."""
    self.check(params)
    return self._scene_at(params)

  def _scene_at(self, params: Params) -> scene_lib.Scene:
    d = self.scene.to_dict()
    for k, i in enumerate(self.indices):
      o = dict(d["obstacles"][i], x=float(params["x"][k]))
      if "size" in params:
        keys = scene_lib.OBSTACLE_SHAPES[self.shapes[k]]
        o.update({key: float(v) for key, v in
                  zip(keys, np.asarray(params["size"][k]))})
      d["obstacles"][i] = o
    return scene_lib.Scene.from_dict(d)

  def check(self, params: Params) -> None:
    """Raises InputError when ``params`` lie outside the allowed ranges, an
    obstacle leaves the ramp or two obstacles overlap."""
    x = np.asarray(params["x"])
    if x.shape != (self.count,):
      raise scene_lib.InputError(
          f"x has shape {x.shape}: allowed: ({self.count},), one position "
          "per designed obstacle")
    for k in range(self.count):
      try:
        self._single(k).check(self._split(params, k))
      except scene_lib.InputError as e:
        raise scene_lib.InputError(f"designed obstacle {k}: {e}") from None
    self._scene_at(params)        # off the ramp, overlapping: the scene's

  def covering_params(self, step: float) -> list[Params]:
    """Placements whose obstacles together cover everywhere each designed
    obstacle can reach: each swept over x every ``step`` (m) at its largest
    free size, the others at their initial x."""
    params = self.initial()
    if "size" in params:
      params = dict(params, size=jnp.asarray(self.size_range()[..., 1]))
    lo, hi = self.x_range
    return [dict(params, x=params["x"].at[k].set(x))
            for k in range(self.count)
            for x in np.arange(lo, hi + step, step, dtype=np.float32)]


# What the MPM rollouts and the optimisers accept.
AnyPlacement = Placement | MultiPlacement


def with_obstacle(scene: scene_lib.Scene, shape: str, x: float,
                  **sizes: float) -> scene_lib.Scene:
  """``scene`` plus an obstacle (validated; a clear error if off the ramp)."""
  d = scene.to_dict()
  d["obstacles"] = list(d["obstacles"]) + [{"shape": shape, "x": x, **sizes}]
  return scene_lib.Scene.from_dict(d)
