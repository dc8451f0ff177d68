"""How many scenes one ``mpm.simulate_batch`` call should take: the batched
program's memory per scene, measured from XLA's memory analysis, against
the device's free memory.
"""

# The batched chunk program and its padding are the driver's own.
# pylint: disable=protected-access

import dataclasses
import os
from typing import Sequence

import jax

from mpm import programs
from mpm import scene as scene_lib
from mpm import simulation

@dataclasses.dataclass(frozen=True)
class BatchSizing:
  """How many scenes like one ``simulate_batch`` call should take.

  Attributes:
    batch: scenes per call (>= 1).
    per_scene_bytes: device memory each scene adds to the batched program
      (XLA's memory analysis at 1 and 2 scenes: arguments, outputs and
      temporaries).
    fixed_bytes: what the program needs whatever the batch.
    available_bytes: the device memory counted on (None: not known).
    source: where ``available_bytes`` came from, or the fallback taken.
  """
  batch: int
  per_scene_bytes: int
  fixed_bytes: int
  available_bytes: int | None
  source: str


def device_memory_bytes(device=None) -> int | None:
  """Bytes a new program may use on ``device`` (default: the first):
  ``memory_stats()``'s ``bytes_limit`` less ``bytes_in_use``; None where
  the device keeps no such statistics (the CPU)."""
  device = device or jax.devices()[0]
  try:
    stats = device.memory_stats()
  except (AttributeError, NotImplementedError, RuntimeError):
    stats = None
  if not stats or "bytes_limit" not in stats:
    return None
  return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))


def program_bytes(setups: Sequence[simulation.Setup], chunk_frames: int = 50) -> int:
  """Device bytes of the batched chunk program ``simulate_setups`` runs
  for these setups (compiled, not run; XLA's memory analysis)."""
  state, params, field = simulation._stacked(setups, batched=True)
  first = setups[0]
  _, frames = simulation.chunking(first.scene.num_frames, chunk_frames)
  compiled, _ = programs.compiled(
      programs.chunk_program(batched=True, windowed=False), state, params,
      field, first.spec, frames, first.n_substeps)
  m = compiled.memory_analysis()
  if m is None:
    raise NotImplementedError("no memory analysis on this backend")
  return int(m.argument_size_in_bytes + m.output_size_in_bytes +
             m.temp_size_in_bytes - m.alias_size_in_bytes)


def batch_size_for(scene: scene_lib.Scene, *, chunk_frames: int = 50,
                   device=None, fraction: float = 0.8, cpu_batch: int = 8,
                   max_batch: int = 4096) -> BatchSizing:
  """Scenes like ``scene`` per ``simulate_batch`` call that fill a device.

  The per-scene footprint is measured from the compiled batched program at
  1 and 2 scenes (two compilations, seconds). On an accelerator the batch
  is ``fraction`` of the free memory (``device_memory_bytes``) over it.
  Where the device reports no memory (the CPU) the batch is ``cpu_batch``
  (a batch does not fill the CPU's memory but its cores, and more scenes
  per call gain little there: docs/scaling.md), still capped by the
  host's free memory.

  Args:
    scene: a representative scene (the largest of those to batch).
    chunk_frames: as ``simulate_setups``'s.
    device: default the first device.
    fraction: share of the free memory to fill (the rest: XLA's slack).
    cpu_batch: the batch where memory statistics are missing.
    max_batch: upper bound in any case.

  Returns:
    A :class:`BatchSizing`.
  """
  if not 0 < fraction <= 1:
    raise scene_lib.InputError(f"fraction = {fraction}; allowed: (0, 1]")
  s = simulation.setup(scene)
  one, two = program_bytes([s], chunk_frames), program_bytes([s, s],
                                                             chunk_frames)
  per_scene = max(two - one, 1)
  fixed = max(one - per_scene, 0)
  available = device_memory_bytes(device)
  source = "memory_stats: bytes_limit - bytes_in_use"
  if available is None:
    batch = cpu_batch
    source = (f"fallback: {(device or jax.devices()[0]).platform} reports "
              f"no memory_stats; cpu_batch = {cpu_batch}")
    try:  # host memory still bounds it
      host = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
      batch = min(batch, max(1, int((fraction * host - fixed) // per_scene)))
    except (ValueError, OSError, AttributeError):
      pass
  else:
    batch = int((fraction * available - fixed) // per_scene)
  return BatchSizing(max(1, min(batch, max_batch)), per_scene, fixed,
                     available, source)
