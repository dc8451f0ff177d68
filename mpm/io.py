"""Trajectory files (HDF5), in the layout of docs/dataset.md ("Files").

Root attributes: ``format_version``, ``dim``, ``frame_dt``, ``bounds``
([[x_min, x_max], [y_min, y_max]]), ``connectivity_radius``,
``sequence_length`` and the normalisation statistics ``vel_mean``,
``vel_std``, ``acc_mean``, ``acc_std``. One group per trajectory (named
``00000``, ``00001``, ...) holds ``positions`` float32 [T, N, 2] (sand only),
``particle_type`` int32 [N], ``boundary_positions`` float32 [Nb, 2],
``boundary_type`` int32 [Nb], and attributes ``scene`` (JSON), ``seed`` and
``wall_time_s``.

Velocities and accelerations in the statistics are finite differences of
positions per frame (metres per frame, per frame^2), as in DeepMind's and
geoelements' GNS datasets. Files are written to a temporary name and renamed,
so a reader never sees half a file.

This module is the file format, so besides numpy it needs h5py; the solver
modules of ``mpm`` import only jax and numpy, and ``import mpm`` does not
load this one.
"""

import csv
import dataclasses
import io
import json
import os
import socket
from typing import Iterable, Iterator, Sequence

import h5py
import numpy as np

from mpm import geometry
from mpm import scene as scene_lib

FORMAT_VERSION = 1
DEFAULT_CONNECTIVITY_RADIUS = 0.015


class FormatError(ValueError):
  """A trajectory file is missing, corrupt or not in this format."""


def temp_path(path: str) -> str:
  """A temporary name beside ``path`` for one writer: ``<path>.tmp-<host>-
  <pid>``. Processes on different hosts sharing a filesystem may have the
  same pid; the host name keeps their temporary files apart."""
  host = socket.gethostname().replace("/", "_") or "host"
  return f"{path}.tmp-{host}-{os.getpid()}"


def temp_writer(tmp: str) -> tuple[str | None, int | None]:
  """(host, pid) of a ``temp_path`` name; host None for the older
  ``<path>.tmp-<pid>`` names, pid None if it is not one of ours."""
  tail = tmp.rsplit(".tmp-", 1)[-1]
  host, _, pid = tail.rpartition("-")
  if not pid.isdigit():
    return None, None
  return (host or None), int(pid)


@dataclasses.dataclass(frozen=True)
class Trajectory:
  """One trajectory and its scene.

  Attributes:
    positions: float32 [T, N, 2] moving particle positions (m); frame 0 is
      the start.
    boundary_positions: float32 [Nb, 2] static boundary particles (m).
    boundary_type: int32 [Nb] (``mpm.RAMP_TYPE`` or ``mpm.OBSTACLE_TYPE``).
    scene: the scene simulated.
    seed: the sampler seed (-1 when the scene was not sampled).
    wall_time_s: simulation time, compilation excluded (s).
    particle_type: int32 [N]; default all ``mpm.SAND_TYPE``.
  """
  positions: np.ndarray
  boundary_positions: np.ndarray
  boundary_type: np.ndarray
  scene: scene_lib.Scene
  seed: int = -1
  wall_time_s: float = float("nan")
  particle_type: np.ndarray | None = None

  def __post_init__(self):
    if self.particle_type is None:
      object.__setattr__(self, "particle_type", np.full(
          np.shape(self.positions)[1], geometry.SAND_TYPE, np.int32))

  @classmethod
  def from_result(cls, result, seed: int = -1) -> "Trajectory":
    """From an ``mpm.SimulationResult``."""
    return cls(result.positions, result.boundary_positions,
               result.boundary_types, result.scene, seed, result.wall_time_s)


def finite_difference_stats(positions: Sequence[np.ndarray],
                            stride: int = 1) -> dict:
  """Mean and std [2] of velocities and accelerations per ``stride`` frames.

  Velocities x[f + k] - x[f] and accelerations x[f + 2k] - 2 x[f + k] + x[f]
  at every frame f, for k = ``stride``.

  Args:
    positions: trajectories, each [T, N, 2] with T >= 2 stride + 1.
    stride: k >= 1.

  Returns:
    dict with vel_mean, vel_std, acc_mean, acc_std (float64 [2]).
  """
  # Accumulate sums rather than concatenating: datasets exceed memory.
  sums = {k: np.zeros(2) for k in ("v", "v2", "a", "a2")}
  counts = {"v": 0, "a": 0}
  for x in positions:
    x = np.asarray(x, np.float64)
    k = stride
    if x.shape[0] < 2 * k + 1:
      raise ValueError(f"positions: need at least {2 * k + 1} frames for "
                       f"accelerations at stride {k}, got shape {x.shape}")
    v = (x[k:] - x[:-k]).reshape(-1, 2)
    a = (x[2 * k:] - 2 * x[k:-k] + x[:-2 * k]).reshape(-1, 2)
    sums["v"] += v.sum(0)
    sums["v2"] += (v * v).sum(0)
    sums["a"] += a.sum(0)
    sums["a2"] += (a * a).sum(0)
    counts["v"] += len(v)
    counts["a"] += len(a)
  stats = {}
  for name, key in (("vel", "v"), ("acc", "a")):
    mean = sums[key] / counts[key]
    var = np.maximum(sums[key + "2"] / counts[key] - mean**2, 0.0)
    stats[f"{name}_mean"] = mean
    stats[f"{name}_std"] = np.sqrt(var)
  return stats


def write_trajectories(path: str, trajectories: Sequence[Trajectory], *,
                       stats: dict | None = None,
                       connectivity_radius: float = DEFAULT_CONNECTIVITY_RADIUS
                       ) -> None:
  """Writes trajectories to ``path`` atomically.

  Args:
    stats: normalisation statistics (see ``finite_difference_stats``);
      default: computed from these trajectories.
  """
  if stats is None:
    stats = finite_difference_stats([t.positions for t in trajectories])
  write_split(path, trajectories, stats=stats,
              connectivity_radius=connectivity_radius)


def write_split(path: str, trajectories: Iterable[Trajectory], *, stats: dict,
                connectivity_radius: float = DEFAULT_CONNECTIVITY_RADIUS
                ) -> list[float]:
  """Streams trajectories into ``path`` (atomically: all or nothing).

  Returns:
    Each trajectory's ``wall_time_s``, in order.
  """
  tmp = temp_path(path)
  wall_times = []
  try:
    with h5py.File(tmp, "w") as f:
      first = None
      for i, t in enumerate(trajectories):
        _check_trajectory(t)
        if first is None:
          first = t.scene
          write_header(f, first, len(t.positions), stats, connectivity_radius)
        elif (t.scene.domain, t.scene.frame_dt) != (first.domain,
                                                     first.frame_dt):
          raise ValueError("write_split: all trajectories of a file need the "
                           "same domain and frame_dt")
        write_group(f, f"{i:05d}", t)
        wall_times.append(t.wall_time_s)
      if first is None:
        raise ValueError("write_split: no trajectories given")
    os.replace(tmp, path)
  finally:
    if os.path.exists(tmp):
      os.remove(tmp)
  return wall_times


def write_text(path: str, text: str) -> None:
  """Writes ``text`` to ``path`` atomically (a temporary file, renamed)."""
  tmp = temp_path(path)
  with open(tmp, "w") as f:
    f.write(text)
  os.replace(tmp, path)


def write_csv(path: str, rows: Sequence[dict]) -> None:
  """Rows (dicts; the columns are the first row's keys, others ignored) as
  CSV, atomically; nothing is written for no rows."""
  if not rows:
    return
  text = io.StringIO(newline="")
  writer = csv.DictWriter(text, fieldnames=list(rows[0]),
                          extrasaction="ignore")
  writer.writeheader()
  writer.writerows(rows)
  write_text(path, text.getvalue())


def write_json(path: str, obj) -> None:
  """Writes ``obj`` as JSON atomically."""
  write_text(path, json.dumps(obj, indent=2))


def read_json(path: str):
  """The JSON value stored in ``path`` (``write_json``'s inverse)."""
  with open(path) as f:
    return json.load(f)


def write_header(f: h5py.File, scene: scene_lib.Scene, sequence_length: int,
                 stats: dict, connectivity_radius: float) -> None:
  """Writes the root attributes of a file."""
  f.attrs["format_version"] = FORMAT_VERSION
  f.attrs["dim"] = 2
  f.attrs["frame_dt"] = scene.frame_dt
  f.attrs["bounds"] = np.array([[0.0, scene.domain.width],
                                [0.0, scene.domain.height]])
  f.attrs["connectivity_radius"] = connectivity_radius
  f.attrs["sequence_length"] = sequence_length
  for key in ("vel_mean", "vel_std", "acc_mean", "acc_std"):
    f.attrs[key] = np.asarray(stats[key], np.float64)


def write_group(f: h5py.File, name: str, t: Trajectory) -> None:
  """Writes one trajectory as group ``name``."""
  g = f.create_group(name)
  # Uncompressed, chunked by frame: float32 positions barely compress and a
  # random 7-frame window then reads in ~0.1 ms (measured on the development
  # CPU).
  g.create_dataset("positions", data=np.asarray(t.positions, np.float32),
                   chunks=(1,) + t.positions.shape[1:])
  g.create_dataset("particle_type", data=np.asarray(t.particle_type,
                                                   np.int32))
  g.create_dataset("boundary_positions",
                   data=np.asarray(t.boundary_positions, np.float32))
  g.create_dataset("boundary_type", data=np.asarray(t.boundary_type, np.int32))
  g.attrs["scene"] = t.scene.to_json()
  g.attrs["seed"] = int(t.seed)
  g.attrs["wall_time_s"] = float(t.wall_time_s)


def _check_trajectory(t: Trajectory) -> None:
  x = np.asarray(t.positions)
  if x.ndim != 3 or x.shape[-1] != 2:
    raise ValueError(f"positions: expected [T, N, 2], got {x.shape}")
  if not np.all(np.isfinite(x)):
    raise ValueError(f"positions of scene {t.scene.name!r} are not finite; "
                     "refusing to write them as data")
  if np.shape(t.particle_type) != (x.shape[1],):
    raise ValueError(f"particle_type: expected [{x.shape[1]}], got "
                     f"{np.shape(t.particle_type)}")
  if np.asarray(t.boundary_positions).shape != (len(t.boundary_type), 2):
    raise ValueError("boundary_positions: expected [Nb, 2] matching "
                     f"boundary_type [Nb], got "
                     f"{np.asarray(t.boundary_positions).shape} and "
                     f"{np.asarray(t.boundary_type).shape}")


def open_file(path: str) -> h5py.File:
  """Opens a trajectory file for reading, checking its format version."""
  if not os.path.exists(path):
    raise FormatError(f"{path}: no such trajectory file")
  try:
    f = h5py.File(path, "r")
  except OSError as e:
    raise FormatError(f"{path}: not a readable HDF5 file ({e})") from e
  version = f.attrs.get("format_version")
  if version != FORMAT_VERSION:
    f.close()
    shown = "missing" if version is None else str(np.asarray(version).item())
    raise FormatError(f"{path}: format_version {shown}; this reader "
                      f"supports {FORMAT_VERSION}")
  return f


def read_group(g: h5py.Group) -> Trajectory:
  """Reads one trajectory group, checking shapes."""
  try:
    positions = g["positions"][()]
    particle_type = g["particle_type"][()]
    boundary_positions = g["boundary_positions"][()]
    boundary_type = g["boundary_type"][()]
    scene = scene_lib.Scene.from_json(g.attrs["scene"])
    seed, wall_time = int(g.attrs["seed"]), float(g.attrs["wall_time_s"])
  except (KeyError, OSError) as e:
    raise FormatError(f"{g.file.filename}:{g.name}: missing or unreadable "
                      f"entry ({e})") from e
  t = Trajectory(positions, boundary_positions, boundary_type, scene, seed,
                 wall_time, particle_type)
  try:
    _check_trajectory(t)
  except ValueError as e:
    raise FormatError(f"{g.file.filename}:{g.name}: {e}") from e
  return t


def read_trajectories(path: str) -> Iterator[Trajectory]:
  """Yields every trajectory of a file, one at a time."""
  with open_file(path) as f:
    for name in sorted(f.keys()):
      yield read_group(f[name])


def read_header(path: str) -> dict:
  """Root attributes of a file as a dict."""
  with open_file(path) as f:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v)
            for k, v in f.attrs.items()}
