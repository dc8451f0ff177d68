"""Scene description: the JSON scene file (docs/physics.md, section 2) as
frozen dataclasses.

A :class:`Scene` says everything one MPM run needs: the domain box, the ramp
profile, the obstacles standing on it, where the sand starts, the material, the
friction of the surfaces and the discretisation. Missing keys take the paper's
defaults; invalid values raise ``InputError`` (a ``ValueError``) naming the
key and the allowed range. Units are SI throughout (metres, seconds,
kilograms, pascals).
"""

import dataclasses
import json
import math
from typing import Any, Mapping, Sequence

import numpy as np

from mpm import constitutive


class InputError(ValueError):
  """A value given by the user (a scene key, a flag) is malformed or out of
  range; the message names it, the value and the allowed values."""

# The paper's ramp, eq. (5): y(x) = sum_k c_k x^k in metres.
PAPER_RAMP_COEFFICIENTS = (0.1086, -0.5179, 1.3434, -1.6513, 0.8923)

# Stiffer sand needs more substeps (c_p grows like sqrt(E)); above this the
# cost runs to hours per trajectory (docs/physics.md, section 6).
MAX_YOUNGS_MODULUS = 1e9  # Pa
# The MPM's time per substep on a CPU (docs/performance.md), for the
# estimate in the error above the bound.
_SECONDS_PER_SUBSTEP = 447e-6

# Size keys of each obstacle shape (metres).
OBSTACLE_SHAPES = {
    "semicircle": ("radius",),
    "rectangle": ("width", "height"),
    "triangle": ("base", "height"),
}


@dataclasses.dataclass(frozen=True)
class Domain:
  """The simulation box [0, width] x [0, height]."""
  width: float = 1.65
  height: float = 1.19


@dataclasses.dataclass(frozen=True)
class Ramp:
  """The ramp's height profile y(x); everything below it is solid.

  Attributes:
    kind: "polynomial" (y = sum_k coefficients[k] x^k) or "polyline"
      (piecewise linear through ``points``, sorted by x, spanning the domain).
  """
  kind: str = "polynomial"
  coefficients: tuple[float, ...] = PAPER_RAMP_COEFFICIENTS
  points: tuple[tuple[float, float], ...] = ()

  def height(self, x):
    """Ramp height [m] at horizontal positions ``x`` (numpy, any shape)."""
    x = np.asarray(x, dtype=np.float64)
    if self.kind == "polyline":
      px, py = np.asarray(self.points, dtype=np.float64).T
      return np.interp(x, px, py)
    return np.polynomial.polynomial.polyval(x, self.coefficients)


@dataclasses.dataclass(frozen=True)
class Obstacle:
  """A solid standing on the ramp, its base centred at (x, ramp(x)).

  The shape is oriented along the local surface: its height is measured along
  the ramp's normal at x. Only the size keys of the shape are set (see
  ``OBSTACLE_SHAPES``).
  """
  shape: str
  x: float
  radius: float | None = None
  width: float | None = None
  height: float | None = None
  base: float | None = None

  @property
  def half_width(self) -> float:
    """Half of the base's length along the surface [m]."""
    return {"semicircle": self.radius, "rectangle": (self.width or 0) / 2,
            "triangle": (self.base or 0) / 2}[self.shape]

  @property
  def reach(self) -> float:
    """Radius [m] around the base centre that contains the whole obstacle."""
    if self.shape == "semicircle":
      return self.radius
    return math.hypot(self.half_width, self.height)

  def to_dict(self) -> dict[str, Any]:
    sizes = {k: getattr(self, k) for k in OBSTACLE_SHAPES[self.shape]}
    return {"shape": self.shape, "x": self.x, **sizes}


@dataclasses.dataclass(frozen=True)
class Granular:
  """Where the sand starts: lattice points inside ``box`` and above the solid.

  Attributes:
    box: (x_min, y_min, x_max, y_max) in metres.
    spacing: lattice spacing [m]; each particle stands for spacing^2 of sand.
    num_particles: if set, the box is filled from its lowest row upwards with
      exactly this many particles (a heap resting on the ramp); otherwise every
      free lattice point in the box holds a particle.
  """
  box: tuple[float, float, float, float] = (1.25, 0.5, 1.46, 1.19)
  spacing: float = 0.005
  num_particles: int | None = 1000


@dataclasses.dataclass(frozen=True)
class Material:
  """Dry sand: Hencky elasticity with a Drucker-Prager yield surface, or
  with the rate-dependent friction of the mu(I) rheology.

  Attributes:
    rheology: "drucker_prager" (constant friction, the paper's) or "mu_i"
      (mu = mu_s + (mu_2 - mu_s) / (I_0 / I + 1), I the inertial number).
    mu_s, mu_2, I_0, grain_diameter (m), grain_density (kg/m^3): the mu(I)
      parameters (docs/physics.md); None with Drucker-Prager.
    alpha_reg: with "mu_i_regularized" (mu(I) with Barker & Gray 2017's
      partial regularisation below the inertial number where the plain law
      turns ill-posed), the exponent of its low-I branch; None otherwise.
    phi_max, phi_min, dilatancy, phi_0: with "mu_i_compressible" (mu(I)
      with a volume fraction phi, starting at phi_0, relaxing toward
      phi_eq(I) = phi_max - (phi_max - phi_min) I through the dilatancy
      tan(psi) = dilatancy (phi - phi_eq)); None otherwise.
  """
  density: float = 1538.0            # kg / m^3
  youngs_modulus: float = 3.537e5    # Pa
  poisson_ratio: float = 0.3
  friction_angle_deg: float = 35.0   # internal friction angle, degrees
  rheology: str = "drucker_prager"
  mu_s: float | None = None
  mu_2: float | None = None
  I_0: float | None = None  # pylint: disable=invalid-name (the literature's)
  grain_diameter: float | None = None
  grain_density: float | None = None
  alpha_reg: float | None = None
  phi_max: float | None = None
  phi_min: float | None = None
  dilatancy: float | None = None
  phi_0: float | None = None

  def to_dict(self) -> dict[str, Any]:
    """The JSON form; the mu(I) keys only with that rheology (so the
    paper's files are unchanged)."""
    d = dataclasses.asdict(self)
    for key in RHEOLOGY_KEYS:
      if key not in RHEOLOGIES[self.rheology]:
        del d[key]
    if self.rheology == "drucker_prager":
      del d["rheology"]
    return d


# The rheologies and the keys each adds to the material.
RHEOLOGIES = {
    "drucker_prager": (),
    "mu_i": ("mu_s", "mu_2", "I_0", "grain_diameter", "grain_density"),
    "mu_i_regularized": ("mu_s", "mu_2", "I_0", "grain_diameter",
                         "grain_density", "alpha_reg"),
    "mu_i_compressible": ("mu_s", "mu_2", "I_0", "grain_diameter",
                          "grain_density", "phi_max", "phi_min",
                          "dilatancy", "phi_0"),
}
RHEOLOGY_KEYS = tuple(dict.fromkeys(k for keys in RHEOLOGIES.values()
                                    for k in keys))
# mu(I) defaults: mu_2 - mu_s and I_0 of glass beads (Jop, Forterre &
# Pouliquen 2006), sand grains of 0.5 mm, quartz.
MU_I_DELTA = 0.26
MU_I_I0 = 0.279
MU_I_GRAIN_DIAMETER = 0.0005  # m
MU_I_GRAIN_DENSITY = 2650.0   # kg / m^3
# Barker & Gray (2017)'s exponent of the regularised low-I branch.
MU_I_ALPHA_REG = 1.9
# The compressible law's dilatancy law phi_eq(I) (glass beads, as commonly
# quoted) and Pailha & Pouliquen (2009)'s K of tan psi = K (phi - phi_eq).
MU_I_PHI_MAX = 0.6
MU_I_PHI_MIN = 0.4
MU_I_DILATANCY = 4.09


@dataclasses.dataclass(frozen=True)
class Solver:
  """Discretisation: grid spacing [m] and CFL number.

  A scene file without ``dx`` gets twice the particle spacing (2 x 2 particles
  per cell).
  """
  dx: float = 0.01
  cfl: float = 0.4


@dataclasses.dataclass(frozen=True)
class Scene:
  """One MPM run. See docs/physics.md, section 2, for the JSON form."""
  domain: Domain = Domain()
  ramp: Ramp = Ramp()
  obstacles: tuple[Obstacle, ...] = ()
  granular: Granular = Granular()
  material: Material = Material()
  boundary_friction: float = 0.5
  wall_friction: float = 0.0
  solver: Solver = Solver()
  num_frames: int = 600
  frame_dt: float = 0.0025
  name: str = "scene"

  @property
  def dx(self) -> float:
    """Grid spacing [m]."""
    return self.solver.dx

  def to_dict(self) -> dict[str, Any]:
    ramp = ({"kind": "polyline", "points": [list(p) for p in self.ramp.points]}
            if self.ramp.kind == "polyline" else
            {"kind": "polynomial",
             "coefficients": list(self.ramp.coefficients)})
    granular = {"box": list(self.granular.box),
                "spacing": self.granular.spacing}
    if self.granular.num_particles is not None:
      granular["num_particles"] = self.granular.num_particles
    return {
        "name": self.name,
        "domain": dataclasses.asdict(self.domain),
        "ramp": ramp,
        "obstacles": [o.to_dict() for o in self.obstacles],
        "granular": granular,
        "material": self.material.to_dict(),
        "boundary_friction": self.boundary_friction,
        "wall_friction": self.wall_friction,
        "solver": {"dx": self.dx, "cfl": self.solver.cfl},
        "num_frames": self.num_frames,
        "frame_dt": self.frame_dt,
    }

  def to_json(self, **kwargs) -> str:
    return json.dumps(self.to_dict(), **kwargs)

  @classmethod
  def from_dict(cls, d: Mapping[str, Any]) -> "Scene":
    """Parses and validates a scene dictionary (the JSON contract)."""
    return _parse_scene(d)

  @classmethod
  def from_json(cls, text: str) -> "Scene":
    try:
      d = json.loads(text)
    except json.JSONDecodeError as e:
      raise InputError(f"scene is not valid JSON: {e}") from e
    return _parse_scene(d)

  @classmethod
  def load(cls, path: str) -> "Scene":
    with open(path) as f:
      return cls.from_json(f.read())


# ----------------------------------------------------------------- parsing ---


def _check_keys(d: Any, allowed: Sequence[str], where: str) -> None:
  if not isinstance(d, Mapping):
    raise InputError(f"{where}: expected an object with keys {list(allowed)}, "
                     f"got {type(d).__name__}")
  unknown = sorted(set(d) - set(allowed))
  if unknown:
    raise InputError(f"{where}: unknown key(s) {unknown}; allowed keys are "
                     f"{list(allowed)}")


def _number(d: Mapping[str, Any], key: str, default: Any, where: str,
            lo: float = -math.inf, hi: float = math.inf,
            lo_open: bool = False, hi_open: bool = False) -> float:
  """Reads d[key] as a finite float in the interval [lo, hi] (or open ends)."""
  value = d.get(key, default)
  name = f"{where}.{key}" if where else key
  if isinstance(value, bool) or not isinstance(value, (int, float)):
    raise InputError(f"{name}: expected a number, got {value!r}")
  value = float(value)
  too_low = value <= lo if lo_open else value < lo
  too_high = value >= hi if hi_open else value > hi
  if not math.isfinite(value) or too_low or too_high:
    interval = (("(" if lo_open else "[") + f"{lo:g}, {hi:g}" +
                (")" if hi_open else "]"))
    raise InputError(f"{name} = {value:g} is out of range; allowed: {interval}")
  return value


def _integer(d: Mapping[str, Any], key: str, default: Any, where: str,
             lo: int) -> int:
  value = d.get(key, default)
  name = f"{where}.{key}" if where else key
  if isinstance(value, bool) or not isinstance(value, int):
    raise InputError(f"{name}: expected an integer >= {lo}, got {value!r}")
  if value < lo:
    raise InputError(f"{name} = {value} is out of range; allowed: >= {lo}")
  return value


def with_rheology(scene: "Scene", rheology: str) -> "Scene":
  """``scene`` with sand of ``rheology`` (``RHEOLOGIES``), its parameters
  at their defaults for the scene's friction angle."""
  d = scene.to_dict()
  for key in ("rheology",) + RHEOLOGY_KEYS:
    d["material"].pop(key, None)
  if rheology != "drucker_prager":
    d["material"]["rheology"] = rheology
  return Scene.from_dict(d)


def _parse_rheology(md: Mapping[str, Any], density: float,
                    friction_angle_deg: float) -> dict[str, Any]:
  """The material's rheology and its parameters (defaults filled in)."""
  rheology = md.get("rheology", "drucker_prager")
  if rheology not in RHEOLOGIES:
    raise InputError(f"material.rheology = {rheology!r}; allowed: one of "
                     f"{list(RHEOLOGIES)}")
  unused = [k for k in RHEOLOGY_KEYS
            if k in md and k not in RHEOLOGIES[rheology]]
  if unused:
    users = [r for r in RHEOLOGIES if set(unused) <= set(RHEOLOGIES[r])]
    raise InputError(f"material: {unused} do not apply with "
                     f"material.rheology = {rheology!r}; allowed: a "
                     f"rheology of {users}, or leave them out")
  if rheology == "drucker_prager":
    return {}
  # Default: the friction of Drucker-Prager at friction_angle_deg, which in
  # plane strain yields at tau_eq = sin(phi) p (Mohr-Coulomb in 2D), so the
  # two rheologies are the same sand at rest and differ only in the rate.
  mu_s = _number(md, "mu_s", math.sin(math.radians(friction_angle_deg)),
                 "material", 0, 10, lo_open=True)
  mu_2 = _number(md, "mu_2", mu_s + MU_I_DELTA, "material", 0, 10,
                 lo_open=True)
  if mu_2 <= mu_s:
    raise InputError(f"material.mu_2 = {mu_2:g} is not above material.mu_s "
                     f"= {mu_s:g}; allowed: mu_2 > mu_s (the friction rises "
                     "with the inertial number)")
  grain_density = _number(md, "grain_density", MU_I_GRAIN_DENSITY,
                          "material", 0, 1e5, lo_open=True)
  if grain_density < density:
    raise InputError(f"material.grain_density = {grain_density:g} is below "
                     f"material.density = {density:g}; allowed: >= the bulk "
                     "density (grains and the voids between them)")
  out = {"rheology": rheology, "mu_s": mu_s, "mu_2": mu_2,
         "I_0": _number(md, "I_0", MU_I_I0, "material", 0, 10,
                        lo_open=True),
         "grain_diameter": _number(md, "grain_diameter", MU_I_GRAIN_DIAMETER,
                                   "material", 0, 0.1, lo_open=True),
         "grain_density": grain_density}
  if rheology == "mu_i_regularized":
    out["alpha_reg"] = _number(md, "alpha_reg", MU_I_ALPHA_REG, "material",
                               0, 10, lo_open=True)
    _check_regularizable(mu_s, mu_2, out["I_0"], out["alpha_reg"])
  if rheology == "mu_i_compressible":
    phi_max = _number(md, "phi_max", MU_I_PHI_MAX, "material", 0, 1, True,
                      True)
    phi_min = _number(md, "phi_min", MU_I_PHI_MIN, "material", 0, 1, True,
                      True)
    if phi_min >= phi_max:
      raise InputError(f"material.phi_min = {phi_min:g} is not below "
                       f"material.phi_max = {phi_max:g}; allowed: 0 < phi_min "
                       "< phi_max < 1 (sand dilates as it flows faster)")
    # By default the sand starts at phi_eq(0), the critical state at rest:
    # there the same sand as mu(I)'s (a denser start is stronger).
    out.update(
        phi_max=phi_max, phi_min=phi_min,
        dilatancy=_number(md, "dilatancy", MU_I_DILATANCY, "material", 0,
                          100),
        phi_0=_number(md, "phi_0", phi_max, "material", 0, 1, True, True))
  return out


def _check_regularizable(mu_s: float, mu_2: float, i_0: float,
                         alpha_reg: float) -> None:
  """Refuses parameters the partial regularisation cannot serve: a plain law
  ill-posed at every I (no threshold to join at), or a low-I branch that is
  ill-posed itself (there nu = I mu' / mu = mu^2 / (2 alpha_reg))."""
  i_n = constitutive.regularization_threshold(mu_s, mu_2, i_0)
  if i_n is None:
    ok = [m / 100 for m in range(1, 100) if constitutive.
          regularization_threshold(m / 100, m / 100 + mu_2 - mu_s, i_0)]
    hint = (f"mu_s <= {max(ok):.2f} at this mu_2 - mu_s and I_0" if ok else
            "a larger mu_2 - mu_s")
    raise InputError(
        f"material: mu(I) with mu_s = {mu_s:.3g}, mu_2 = {mu_2:.3g}, I_0 = "
        f"{i_0:.3g} is ill-posed at every inertial number (Barker & Gray "
        "2017), so material.rheology = 'mu_i_regularized' has no threshold "
        f"to regularise below; allowed: {hint} (docs/physics.md, section 12)")
  mu_n = constitutive.plain_mu(i_n, mu_s, mu_2, i_0)
  mu = np.linspace(1e-3, mu_n, 200)
  if np.any(constitutive.ill_posedness(1.0, mu, mu**3 / (2 * alpha_reg)) >
            1e-9):
    raise InputError(
        f"material.alpha_reg = {alpha_reg:g}: the regularised branch is "
        f"itself ill-posed below mu(I_N) = {mu_n:.3g}; allowed: a smaller "
        "alpha_reg (Barker & Gray 2017 use 1.9)")


def _parse_ramp(d: Mapping[str, Any], domain: Domain) -> Ramp:
  kind = d.get("kind", "polynomial")
  if kind == "polynomial":
    _check_keys(d, ("kind", "coefficients"), "ramp")
    coefficients = d.get("coefficients", PAPER_RAMP_COEFFICIENTS)
    if (not isinstance(coefficients, (list, tuple)) or not coefficients or
        not all(isinstance(c, (int, float)) and math.isfinite(c)
                for c in coefficients)):
      raise InputError("ramp.coefficients: expected a non-empty list of "
                       "finite numbers c_k with y(x) = sum c_k x^k, got "
                       f"{coefficients!r}")
    return Ramp("polynomial", tuple(float(c) for c in coefficients))
  if kind == "polyline":
    _check_keys(d, ("kind", "points"), "ramp")
    points = d.get("points")
    ok = (isinstance(points, (list, tuple)) and len(points) >= 2 and
          all(isinstance(p, (list, tuple)) and len(p) == 2 for p in points))
    if not ok:
      raise InputError("ramp.points: expected a list of at least two [x, y] "
                       f"pairs, got {points!r}")
    pts = np.asarray(points, dtype=np.float64)
    if not np.all(np.isfinite(pts)) or np.any(np.diff(pts[:, 0]) <= 0):
      raise InputError("ramp.points: x must be finite and strictly increasing")
    if pts[0, 0] > 0 or pts[-1, 0] < domain.width:
      raise InputError(f"ramp.points: must span the domain; x range "
                       f"[{pts[0, 0]:g}, {pts[-1, 0]:g}] must cover "
                       f"[0, {domain.width:g}]")
    return Ramp("polyline", points=tuple((float(x), float(y)) for x, y in pts))
  raise InputError(f"ramp.kind: unknown kind {kind!r}; allowed: "
                   "'polynomial', 'polyline'")


def _parse_obstacle(d: Mapping[str, Any], i: int, domain: Domain,
                    ramp: Ramp) -> Obstacle:
  where = f"obstacles[{i}]"
  if not isinstance(d, Mapping) or d.get("shape") not in OBSTACLE_SHAPES:
    shape = d.get("shape") if isinstance(d, Mapping) else d
    raise InputError(f"{where}.shape: unknown shape {shape!r}; allowed: "
                     f"{list(OBSTACLE_SHAPES)}")
  shape = d["shape"]
  sizes = OBSTACLE_SHAPES[shape]
  _check_keys(d, ("shape", "x") + sizes, where)
  if "x" not in d:
    raise InputError(f"{where}.x: missing; the base centre's horizontal "
                     f"position, allowed: (0, {domain.width:g})")
  values = {}
  for key in sizes:
    if key not in d:
      raise InputError(f"{where}.{key}: missing; a {shape} needs {list(sizes)}")
    values[key] = _number(d, key, None, where, lo=0.0, hi=min(
        domain.width, domain.height) / 2, lo_open=True)
  x = _number(d, "x", None, where, lo=0.0, hi=domain.width, lo_open=True,
              hi_open=True)
  obstacle = Obstacle(shape, x, **values)
  reach = obstacle.reach
  if x - reach < 0 or x + reach > domain.width:
    raise InputError(f"{where}.x = {x:g}: the obstacle (reach {reach:g} m) "
                     f"leaves the domain; allowed: [{reach:g}, "
                     f"{domain.width - reach:g}]")
  base_y = float(ramp.height(x))
  if not 0.0 <= base_y <= domain.height - reach:
    raise InputError(f"{where}.x = {x:g}: off the ramp; the ramp there is at "
                     f"y = {base_y:.3f} m, and the obstacle needs the ramp "
                     f"within [0, {domain.height - reach:.3f}] m")
  return obstacle


def _parse_scene(d: Mapping[str, Any]) -> Scene:
  allowed = [f.name for f in dataclasses.fields(Scene)]
  _check_keys(d, allowed, "scene")
  name = d.get("name", "scene")
  if not isinstance(name, str) or not name:
    raise InputError(f"name: expected a non-empty string, got {name!r}")

  dd = d.get("domain", {})
  _check_keys(dd, ("width", "height"), "domain")
  domain = Domain(_number(dd, "width", 1.65, "domain", 0, math.inf, True),
                  _number(dd, "height", 1.19, "domain", 0, math.inf, True))

  ramp = _parse_ramp(d.get("ramp", {}), domain)

  raw_obstacles = d.get("obstacles", [])
  if not isinstance(raw_obstacles, (list, tuple)):
    raise InputError(f"obstacles: expected a list, got {raw_obstacles!r}")
  obstacles = tuple(_parse_obstacle(o, i, domain, ramp)
                    for i, o in enumerate(raw_obstacles))
  for i, a in enumerate(obstacles):
    for j in range(i):
      b = obstacles[j]
      gap = abs(a.x - b.x)
      need = a.reach + b.reach
      if gap < need:
        raise InputError(
            f"obstacles[{i}].x = {a.x:g}: overlaps obstacles[{j}] at x = "
            f"{b.x:g}; base centres must be at least {need:.3f} m apart")

  # Without a granular block the paper's default heap; with one, a box without
  # num_particles is filled completely.
  gd = d.get("granular", dataclasses.asdict(Granular()))
  _check_keys(gd, ("box", "spacing", "num_particles"), "granular")
  box = gd.get("box", Granular.box)
  if (not isinstance(box, (list, tuple)) or len(box) != 4 or
      not all(isinstance(v, (int, float)) for v in box)):
    raise InputError(f"granular.box: expected [x_min, y_min, x_max, y_max], "
                     f"got {box!r}")
  x0, y0, x1, y1 = (float(v) for v in box)
  if not (0 <= x0 < x1 <= domain.width and 0 <= y0 < y1 <= domain.height):
    raise InputError(f"granular.box = {list(box)}: must satisfy 0 <= x_min < "
                     f"x_max <= {domain.width:g} and 0 <= y_min < y_max <= "
                     f"{domain.height:g}")
  spacing = _number(gd, "spacing", Granular.spacing, "granular", 0,
                    min(x1 - x0, y1 - y0), lo_open=True)
  if np.all(ramp.height(np.linspace(x0, x1, 101)) >= y1):
    raise InputError(f"granular.box = {list(box)}: lies inside the ramp "
                     "(the ramp is above y_max everywhere in [x_min, x_max]); "
                     "allowed: a box reaching above the ramp surface")
  num_particles = gd.get("num_particles", None)
  if num_particles is not None:
    num_particles = _integer(gd, "num_particles", None, "granular", 1)
  granular = Granular((x0, y0, x1, y1), spacing, num_particles)

  sd = d.get("solver", {})
  _check_keys(sd, ("dx", "cfl"), "solver")
  dx = _number(sd, "dx", 2.0 * spacing, "solver", 0,
               min(domain.width, domain.height) / 4, lo_open=True)
  if spacing > dx:
    raise InputError(f"granular.spacing = {spacing:g} is larger than "
                     f"solver.dx = {dx:g}; allowed: spacing <= dx")
  solver = Solver(dx, _number(sd, "cfl", Solver.cfl, "solver", 0, 1,
                              lo_open=True))
  frame_dt = _number(d, "frame_dt", 0.0025, "", 0, 1, lo_open=True)
  num_frames = _integer(d, "num_frames", 600, "", 1)

  md = d.get("material", {})
  _check_keys(md, [f.name for f in dataclasses.fields(Material)], "material")
  density = _number(md, "density", Material.density, "material", 0,
                    lo_open=True)
  poisson_ratio = _number(md, "poisson_ratio", Material.poisson_ratio,
                          "material", 0.0, 0.5, hi_open=True)
  _check_stiffness(md.get("youngs_modulus"), density, poisson_ratio, solver,
                   frame_dt, num_frames)
  friction_angle_deg = _number(md, "friction_angle_deg",
                               Material.friction_angle_deg, "material", 0.0,
                               80.0)
  material = Material(
      density=density,
      youngs_modulus=_number(md, "youngs_modulus", Material.youngs_modulus,
                             "material", 0, MAX_YOUNGS_MODULUS, lo_open=True),
      poisson_ratio=poisson_ratio,
      friction_angle_deg=friction_angle_deg,
      **_parse_rheology(md, density, friction_angle_deg))

  return Scene(
      domain=domain, ramp=ramp, obstacles=obstacles, granular=granular,
      material=material,
      boundary_friction=_number(d, "boundary_friction", 0.5, "", 0.0, 10.0),
      wall_friction=_number(d, "wall_friction", 0.0, "", 0.0, 10.0),
      solver=solver,
      num_frames=num_frames, frame_dt=frame_dt, name=name)


def _check_stiffness(e: Any, density: float, nu: float, solver: Solver,
                     frame_dt: float, num_frames: int) -> None:
  """Refuses a Young's modulus ``e`` above ``MAX_YOUNGS_MODULUS`` with the
  substeps it would cost (the CFL condition of ``simulation``, from the
  wave speed alone: a lower bound)."""
  if (isinstance(e, bool) or not isinstance(e, (int, float)) or
      not MAX_YOUNGS_MODULUS < e < math.inf):
    return  # in range, or not a number: _number says what is allowed
  c_p = math.sqrt(e * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / density)
  per_frame = math.ceil(frame_dt * c_p / (solver.cfl * solver.dx))
  total = per_frame * max(num_frames - 1, 1)
  hours = total * _SECONDS_PER_SUBSTEP / 3600
  raise InputError(
      f"material.youngs_modulus = {e:g} is out of range; allowed: (0, "
      f"{MAX_YOUNGS_MODULUS:g}] Pa: it would need at least {per_frame:,} "
      f"substeps per frame, {total:,} in all (about {hours:.3g} h at "
      f"{_SECONDS_PER_SUBSTEP * 1e6:.0f} us per substep)")
