"""Steady flow down a rough incline: a periodic strip and the Bagnold profile.

The one granular flow with an analytic answer under mu(I) (GDR MiDi 2004):
an infinitely long layer of depth h on a rough base tilted by theta, with
mu_s < tan(theta) < mu_2, reaches a steady uniform flow in which every
depth shears at the same inertial number

    I(theta) = I_0 (tan(theta) - mu_s) / (mu_2 - tan(theta)),

because the stress ratio is tan(theta) at every depth. The pressure is
lithostatic, p = rho g cos(theta) (h - z), so the shear rate
du/dz = I sqrt(p / rho_s) / d grows as sqrt(h - z) and the velocity is

    u(z) = (2/3) (I / d) sqrt(rho g cos(theta) / rho_s) (h^{3/2} - (h - z)^{3/2}).

The strip is ``width`` wide and wraps along x (``GridSpec.periodic_x``), so
a layer a few centimetres long is infinitely long; gravity is tilted instead
of the floor (x runs down the slope, y along the floor's normal). Units: SI.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from mpm import boundary
from mpm import geometry
from mpm import scene as scene_lib
from mpm import simulation
from mpm import solver
from mpm import transfer

# The floor's height in the strip [m]: deep enough that no node the sand can
# reach sees the domain's bottom wall.
FLOOR = 0.01


@dataclasses.dataclass(frozen=True)
class Incline:
  """A tilted periodic strip of sand, ready to step.

  Attributes:
    setup: the strip's initial state and discretisation (its grid wraps
      along x, its boundary is the floor alone, its gravity is tilted).
    theta: the slope [rad].
    depth: the layer's depth h [m] as placed.
  """
  setup: simulation.Setup
  theta: float
  depth: float


def strip_scene(depth: float, *, width: float = 0.02, dx: float = 0.001,
                material: dict | None = None,
                boundary_friction: float = 2.0) -> scene_lib.Scene:
  """The strip's scene: sand ``depth`` [m] deep on a flat floor at ``FLOOR``.

  Args:
    width: the strip's length along the slope [m], a multiple of ``dx``.
    dx: the grid spacing [m]; particles at dx / 2 (four per cell).
    material: the scene's ``material`` entries (default: today's sand).
    boundary_friction: the floor's Coulomb coefficient; well above
      tan(theta) the base does not slip (the analytic profile's condition).
  """
  cells = width / dx
  if abs(cells - round(cells)) > 1e-6 or round(cells) < 4:
    raise ValueError(f"width = {width:g} m: allowed a multiple of dx = "
                     f"{dx:g} m of at least 4 cells")
  if not depth >= 4 * dx:
    raise ValueError(f"depth = {depth:g} m: allowed at least 4 cells "
                     f"({4 * dx:g} m) at dx = {dx:g} m")
  m = {"density": 1500.0, "youngs_modulus": 3.537e5, "poisson_ratio": 0.3,
       "friction_angle_deg": 35.0}
  m.update(material or {})
  return scene_lib.Scene.from_dict({
      "name": "incline",
      "domain": {"width": width, "height": FLOOR + 2 * depth + 4 * dx},
      "ramp": {"kind": "polynomial", "coefficients": [FLOOR]},
      "granular": {"box": [0.0, FLOOR, width, FLOOR + depth],
                   "spacing": dx / 2},
      "material": m, "boundary_friction": boundary_friction,
      "solver": {"dx": dx, "cfl": 0.4}})


def periodic_setup(scene: scene_lib.Scene, theta_deg: float) -> Incline:
  """The strip of ``strip_scene`` on a grid that wraps along x, with
  gravity tilted by ``theta_deg`` (degrees, 0 < theta < 90)."""
  if not 0.0 < theta_deg < 90.0:
    raise ValueError(f"theta = {theta_deg!r} deg: allowed 0 < theta < 90")
  s = simulation.setup(scene, particle_bucket=1)
  width, height, dx = scene.domain.width, scene.domain.height, scene.dx
  spec = transfer.GridSpec(dx, (round(width / dx), s.spec.shape[1]),
                           (0.0, s.spec.origin[1]), periodic_x=True)
  # Every column's nodes from 3 cells under the floor to 2 above it: the
  # floor's condition reaches one cell out, sand sinks at most half a cell.
  rows = np.arange(spec.shape[1])
  y = spec.origin[1] + rows * dx
  band = rows[(y > FLOOR - 3 * dx) & (y < FLOOR + 2 * dx)]
  index = (np.arange(spec.shape[0])[:, None] * spec.shape[1] +
           band[None, :]).reshape(-1).astype(np.int32)
  ramp = geometry.ramp_params(scene.ramp)
  field = boundary.make_field(spec, jnp.asarray(index), width, height, ramp,
                              ())
  # No side walls: zero the x-walls' weights. The top wall is out of reach.
  field = field.replace(wall_weight=field.wall_weight.at[:, 0].set(0.0))
  theta = math.radians(theta_deg)
  params = s.params.replace(gravity=jnp.asarray(
      [simulation.GRAVITY * math.sin(theta),
       -simulation.GRAVITY * math.cos(theta)], jnp.float32))
  s = dataclasses.replace(s, spec=spec, field=field, params=params)
  depth = scene.granular.box[3] - scene.granular.box[1]
  return Incline(s, theta, depth)


def inertial_number(theta: float, material: scene_lib.Material) -> float:
  """I(theta) of steady uniform flow (theta in rad; mu(I) sand), or nan
  where none exists (tan(theta) outside (mu_s, mu_2))."""
  t = math.tan(theta)
  if not material.mu_s < t < material.mu_2:
    return math.nan
  return material.I_0 * (t - material.mu_s) / (material.mu_2 - t)


def bagnold_velocity(z: np.ndarray, depth: float, theta: float,
                     material: scene_lib.Material) -> np.ndarray:
  """The steady velocity u(z) [m/s] at heights ``z`` [m] above the base of a
  layer ``depth`` [m] deep on a slope ``theta`` [rad] (module docstring)."""
  i = inertial_number(theta, material)
  z = np.clip(np.asarray(z, np.float64), 0.0, depth)
  scale = (2.0 / 3.0) * i / material.grain_diameter * math.sqrt(
      material.density * simulation.GRAVITY * math.cos(theta) /
      material.grain_density)
  return scale * (depth**1.5 - (depth - z)**1.5)


def run(incline: Incline, seconds: float, *, frame_dt: float = 0.05,
        max_speed: float = 10.0):
  """Steps the strip for ``seconds``.

  Args:
    frame_dt: seconds between the recorded speeds.
    max_speed: the largest particle speed (m/s) the substep is sized for
      (CFL 0.4 with the P-wave speed); a faster particle stops the run
      with ``SimulationError`` (a layer steeper than its friction keeps
      accelerating).

  Returns:
    (times [T] s, mean downslope velocity of the top tenth of the layer
    [T] m/s, final state).
  """
  s = incline.setup
  n_frames = max(1, round(seconds / frame_dt))
  dt = s.scene.solver.cfl * s.spec.dx / (
      simulation.wave_speed(s.scene.material) + max_speed)
  n_substeps = max(1, math.ceil(frame_dt / dt))
  params = s.params.replace(dt=jnp.asarray(frame_dt / n_substeps, jnp.float32))
  top = FLOOR + 0.9 * incline.depth
  surface = np.asarray(s.state.x[:, 1]) > top

  @jax.jit
  def frame(state):
    state, vmax = solver.advance(state, params, s.field, s.spec, n_substeps)
    return state, vmax, jnp.all(jnp.isfinite(state.x))

  state, speeds = s.state, []
  name = f"incline at {math.degrees(incline.theta):g} deg"
  for k in range(n_frames):
    state, vmax, finite = frame(state)
    if not bool(finite):
      raise simulation.SimulationError(name, k + 1, "non-finite positions")
    if float(vmax) > max_speed:
      raise simulation.SimulationError(
          name, k + 1, f"a particle reached {float(vmax):.3g} m/s at "
          f"{(k + 1) * frame_dt:g} s, past max_speed = {max_speed:g} m/s "
          "the substep was sized for; allowed: a larger max_speed or a "
          "shorter run")
    speeds.append(float(np.mean(np.asarray(state.v[surface, 0]))))
  times = frame_dt * np.arange(1, n_frames + 1)
  return times, np.asarray(speeds), state
