"""What a simulation will cost, from its scene alone, before any work:
particles, grid nodes, substeps, memory (the frames kept included) and time;
and the check that refuses a run that cannot fit this machine's memory.

The figures are estimates, fitted to the solver's compiled chunk program
(XLA's memory analysis at 128-5,504 particles and 594-5,829 nodes) and to the
CPU timings of docs/performance.md; they are meant to tell ten million
particles from ten thousand, not to be exact.
"""

import dataclasses
import math
import os
from typing import Mapping, Sequence

from mpm import scene as scene_lib
from mpm import simulation

# Device bytes per particle of the chunk program without its frames (state
# in and out, the substep's temporaries: ~290 measured), and per stored
# frame of a chunk (float32 x, y and the frame's speed share).
_DEVICE_BYTES_PER_PARTICLE = 420
_BYTES_PER_PARTICLE_FRAME = 8
# Per grid node: the grid's temporaries (~32 measured) and the setup's
# float64 node positions and signed distances on the host.
_BYTES_PER_NODE = 64
# Per lattice point of the granular box (the setup's float64 lattice and
# its signed distances), though num_particles may keep only a few.
_BYTES_PER_LATTICE_POINT = 64
# A process with jax, its runtime and compiled programs.
PROCESS_BYTES = 400 * 2**20
# Time per substep on a CPU: fixed, per particle, per grid node (seconds;
# the paper scene's 1,024 particles and 21,672 nodes: ~447 us).
_SUBSTEP_S = (30e-6, 0.27e-6, 6.5e-9)
# A run this long gets a warning with its estimate.
WARN_SECONDS = 3600.0


@dataclasses.dataclass(frozen=True)
class Cost:
  """The estimated cost of simulating ``scenes`` scenes like one at once.

  Attributes:
    particles: simulated particles per scene.
    lattice_points: lattice points of the granular box the setup evaluates.
    grid_nodes: background grid nodes.
    substeps_per_frame: as ``simulation.substeps_per_frame``.
    num_frames: frames per trajectory, all kept in memory until written.
    scenes: scenes simulated at once (a batch, or worker processes).
    memory_bytes: peak memory of them all (device and host).
    seconds: time to simulate one scene on a CPU.
  """
  particles: int
  lattice_points: int
  grid_nodes: int
  substeps_per_frame: int
  num_frames: int
  scenes: int
  memory_bytes: int
  seconds: float

  def describe(self) -> str:
    """'N particles, G grid nodes, S substeps x F frames: about M, T'."""
    per = " each" if self.scenes > 1 else ""
    return (f"{self.particles:,} particles and {self.grid_nodes:,} grid nodes"
            f"{per}, {self.substeps_per_frame:,} substeps x "
            f"{self.num_frames:,} frames: about {gib(self.memory_bytes)} of "
            f"memory{f' for {self.scenes} at once' if self.scenes > 1 else ''}"
            f" and {duration(self.seconds)} per scene")


def gib(n: float) -> str:
  return f"{n / 2**30:.3g} GiB"


def duration(seconds: float) -> str:
  if seconds >= 3600:
    return f"{seconds / 3600:,.3g} h"
  return f"{seconds / 60:.2g} min" if seconds >= 60 else f"{seconds:.2g} s"


def _lattice(granular: scene_lib.Granular) -> int:
  x0, y0, x1, y1 = granular.box
  per_row = math.floor((x1 - x0) / granular.spacing + 1e-9)
  return per_row * math.floor((y1 - y0) / granular.spacing + 1e-9)


def estimate(scene: scene_lib.Scene, *, scenes: int = 1,
             chunk_frames: int = 50) -> Cost:
  """The cost of simulating ``scene`` (``scenes`` like it at once); pure
  arithmetic on the scene, no array is built.

  Args:
    scene: the scene (its spacing, dx, domain, frames, material).
    scenes: scenes at once: a batch, or worker processes (each one scene).
    chunk_frames: frames per compiled call (``simulate``'s).
  """
  lattice = _lattice(scene.granular)
  n = (lattice if scene.granular.num_particles is None else
       min(scene.granular.num_particles, lattice))
  n = max(n, 1)
  nx = math.ceil(scene.domain.width / scene.dx - 1e-9) + 7  # GridSpec pad 3
  ny = math.ceil(scene.domain.height / scene.dx - 1e-9) + 7
  nodes = nx * ny
  substeps = simulation.substeps_per_frame(scene,
                                           simulation.speed_bound(scene))
  frames = scene.num_frames
  chunk = min(chunk_frames, max(frames - 1, 1))
  device = (n * (_DEVICE_BYTES_PER_PARTICLE + _BYTES_PER_PARTICLE_FRAME *
                 chunk) + nodes * _BYTES_PER_NODE)
  # The frames kept on the host: the chunks, then their concatenation.
  kept = 2 * frames * n * _BYTES_PER_PARTICLE_FRAME
  setup = lattice * _BYTES_PER_LATTICE_POINT
  per_scene = max(device + kept, setup)
  fixed, per_particle, per_node = _SUBSTEP_S
  seconds = (substeps * max(frames - 1, 1) *
             (fixed + per_particle * n + per_node * nodes))
  return Cost(n, lattice, nodes, substeps, frames, scenes,
              int(scenes * (per_scene + PROCESS_BYTES)), seconds)


def machine_memory_bytes(device=None) -> tuple[int | None, str]:
  """(bytes, where from): the device's memory where it reports it
  (``memory_stats``), else this machine's physical memory (``sysconf``)."""
  limit = None
  try:
    stats = device.memory_stats() if device is not None else None
    limit = int(stats["bytes_limit"]) if stats else None
  except (AttributeError, KeyError, NotImplementedError, RuntimeError):
    limit = None
  if limit:
    return limit, f"{getattr(device, 'platform', 'device')} memory"
  try:
    return (os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"),
            "this machine's memory")
  except (ValueError, OSError, AttributeError):
    return None, "unknown"


def _up(x: float) -> float:
  """``x`` rounded up to 3 significant digits (a bound still on the right
  side when shown)."""
  unit = 10.0**(math.floor(math.log10(x)) - 2)
  return round(math.ceil(x / unit * (1 - 1e-12)) * unit, 12)


def _largest(fits, lo: float, hi: float, steps: int = 40) -> float | None:
  """The largest x in [lo, hi] with fits(x) (monotone), or None."""
  if not fits(lo):
    return None
  if fits(hi):
    return hi
  for _ in range(steps):
    mid = (lo + hi) / 2
    lo, hi = (mid, hi) if fits(mid) else (lo, mid)
  return lo


def check_fits(scene: scene_lib.Scene, *, scenes: int = 1,
               chunk_frames: int = 50, memory_bytes: int | None = None,
               memory_source: str = "this machine's memory",
               names: dict[str, str] | None = None) -> Cost:
  """Refuses ``scene`` (``scenes`` at once) if its estimate exceeds
  ``memory_bytes`` (default: ``machine_memory_bytes()``).

  Args:
    names: what to call the settings in the message (keys ``spacing``,
      ``dx``, ``num_frames``, ``scenes``); default the scene's keys; None
      for a setting the caller does not let the user set directly (no fix
      is proposed for it).

  Returns:
    The :class:`Cost`, when it fits.

  Raises:
    InputError: naming the estimate, the memory and the largest
      ``num_frames`` and the smallest spacing that fit.
  """
  names = {"spacing": "granular.spacing", "dx": "solver.dx",
           "num_frames": "num_frames", "scenes": "scenes at once",
           **(names or {})}
  if memory_bytes is None:
    memory_bytes, memory_source = machine_memory_bytes()
  cost = estimate(scene, scenes=scenes, chunk_frames=chunk_frames)
  if memory_bytes is None or cost.memory_bytes <= memory_bytes:
    return cost
  size = lambda s: estimate(s, scenes=scenes,
                            chunk_frames=chunk_frames).memory_bytes
  frames = _largest(lambda f: size(dataclasses.replace(
      scene, num_frames=int(f))) <= memory_bytes, 3, scene.num_frames)
  coarser = lambda k: dataclasses.replace(
      scene, granular=dataclasses.replace(
          scene.granular, spacing=scene.granular.spacing * k),
      solver=dataclasses.replace(scene.solver, dx=scene.dx * k))
  k = _largest(lambda k: size(coarser(1 / k)) <= memory_bytes, 1e-6, 1.0)
  fixes = []
  if frames is not None and int(frames) >= 3 and names["num_frames"]:
    fixes.append(f"{names['num_frames']} <= {int(frames):,}")
  # A coarser lattice must still hold the scene's particles.
  wanted = scene.granular.num_particles or 1
  if (k is not None and names["spacing"] and
      _lattice(coarser(1 / k).granular) >= wanted):
    fixes.append(f"{names['spacing']} >= "
                 f"{_up(scene.granular.spacing / k):g}" +
                 ("" if names["dx"] is None else
                  f" (with {names['dx']} >= {_up(scene.dx / k):g})"))
  one = estimate(scene, chunk_frames=chunk_frames).memory_bytes
  if scenes > 1 and one <= memory_bytes and names["scenes"]:
    fixes.insert(0, f"{names['scenes']} <= {memory_bytes // one}")
  raise scene_lib.InputError(
      f"{names['spacing'] or 'spacing'} = {scene.granular.spacing:g}, "
      f"{names['num_frames'] or 'frames'} = {scene.num_frames:,}: "
      f"{cost.describe()}; "
      f"{memory_source} is {gib(memory_bytes)}; allowed: what fits, e.g. "
      f"{' or '.join(fixes) or 'a smaller scene'}")


def warning(cost: Cost, total_scenes: int = 1, workers: int = 1) -> str | None:
  """A one-line warning with the estimate if the run takes hours, else
  None (``total_scenes`` simulated by ``workers`` processes)."""
  seconds = cost.seconds * total_scenes / max(workers, 1)
  if seconds < WARN_SECONDS:
    return None
  return (f"warning: about {duration(seconds)} of simulating on a CPU "
          f"({cost.describe()}"
          f"{f', {total_scenes:,} scenes' if total_scenes > 1 else ''}); "
          "continuing")


@dataclasses.dataclass(frozen=True)
class Planned:
  """Simulations a job will run: ``count`` scenes like ``scene`` in all,
  ``at_once`` of them in one program (a batch).

  ``names`` is ``check_fits``'s: what the job's flags call the scene's
  settings.
  """
  scene: scene_lib.Scene
  count: int = 1
  at_once: int = 1
  names: Mapping[str, str | None] | None = None


def check_plan(plan: Sequence[Planned], *,
               memory_bytes: int | None = None,
               memory_source: str = "this machine's memory") -> float:
  """Refuses a job any of whose simulations cannot fit (``check_fits``,
  naming the job's flags) before it starts; returns the job's estimated
  seconds of simulating on a CPU (for :func:`plan_warning`)."""
  if memory_bytes is None:
    memory_bytes, memory_source = machine_memory_bytes()
  total = 0.0
  for p in plan:
    cost = check_fits(p.scene, scenes=p.at_once, names=dict(p.names or {}),
                      memory_bytes=memory_bytes, memory_source=memory_source)
    total += p.count * cost.seconds
  return total


def plan_warning(seconds: float, what: str = "this job") -> str | None:
  """A one-line warning if ``seconds`` (``check_plan``'s) is hours."""
  if seconds < WARN_SECONDS:
    return None
  return (f"warning: {what} simulates for about {duration(seconds)} on a "
          "CPU (the MPM alone, estimated before any work); continuing")
