"""mpm: a differentiable MLS-MPM solver for dry sand on a ramp, in JAX.

Typical use::

  import mpm
  scene = mpm.Scene.load("scene.json")
  result = mpm.simulate(scene)          # positions [T, N, 2]

Pure building blocks (``mpm.solver.rollout``, ``mpm.setup``) are for batching,
``jax.grad`` and custom drivers. This package imports only jax and numpy;
``mpm.io`` (trajectory files) and ``mpm.interop`` (npz datasets of other GNS
codes) add h5py and are imported only on request.
"""

from mpm.geometry import KINEMATIC_TYPES
from mpm.geometry import OBSTACLE_TYPE
from mpm.geometry import RAMP_TYPE
from mpm.geometry import SDFGrid
from mpm.geometry import SAND_TYPE
from mpm.geometry import boundary_particles
from mpm.geometry import granular_particles
from mpm.geometry import push_out
from mpm.geometry import sample_sdf
from mpm.geometry import scene_sdf_grid
from mpm.sampler import sample_scene
from mpm.scene import InputError
from mpm.scene import Scene
from mpm.simulation import GRAVITY
from mpm.simulation import SimulationError
from mpm.simulation import SimulationResult
from mpm.simulation import Setup
from mpm.simulation import check_frames
from mpm.simulation import setup
from mpm.simulation import simulate
from mpm.simulation import simulate_batch
from mpm.simulation import simulate_setups
from mpm.solver import MPMState
from mpm.solver import SimParams
from mpm.solver import rollout

__all__ = [
    "GRAVITY", "InputError", "KINEMATIC_TYPES", "OBSTACLE_TYPE", "RAMP_TYPE", "SAND_TYPE",
    "MPMState", "SDFGrid", "Scene", "Setup", "SimParams", "SimulationError",
    "SimulationResult", "boundary_particles", "check_frames",
    "granular_particles", "push_out", "rollout", "sample_scene", "sample_sdf",
    "scene_sdf_grid", "setup", "simulate", "simulate_batch",
    "simulate_setups",
]
