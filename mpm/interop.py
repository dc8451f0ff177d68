"""Import and export the npz + metadata.json layout of public GNS datasets.

DeepMind's *Learning to Simulate* datasets, converted to npz, and
geoelements/gns store one entry per trajectory, ``simulation_trajectory_<i>``:
an object array (positions float [T, N, D], particle_type int [N]), with
kinematic (boundary) particles of type 3 moving with the rest, and a
``metadata.json`` with bounds, sequence_length, default_connectivity_radius,
dim, dt and the velocity/acceleration statistics.

Export writes our boundary particles as type-3 particles repeated over time,
so those codes treat them as kinematic; import turns type-3 particles that
never move into boundary particles and keeps the others as moving particles
with their original types. An imported trajectory carries a placeholder scene
recording only its domain and frame time.

Beside ``mpm.io`` (h5py): ``import mpm`` loads neither.
"""

import json
import os

import numpy as np

from mpm import geometry
from mpm import io as mpm_io
from mpm import scene as scene_lib

KINEMATIC_TYPE = 3
_KEY = "simulation_trajectory_{}"


def export_npz(h5_path: str, npz_path: str,
               metadata_path: str | None = None) -> int:
  """Writes a split file as npz (and its metadata.json); returns the count."""
  entries = {}
  for i, t in enumerate(mpm_io.read_trajectories(h5_path)):
    frames = t.positions.shape[0]
    boundary = np.broadcast_to(t.boundary_positions[None],
                               (frames,) + t.boundary_positions.shape)
    positions = np.concatenate([t.positions, boundary], 1).astype(np.float32)
    types = np.concatenate([t.particle_type, np.full(
        len(t.boundary_type), KINEMATIC_TYPE, np.int64)]).astype(np.int64)
    entry = np.empty(2, dtype=object)
    entry[0], entry[1] = positions, types
    entries[_KEY.format(i)] = entry
  tmp = f"{npz_path}.tmp-{os.getpid()}.npz"
  np.savez_compressed(tmp, **entries)
  os.replace(tmp, npz_path)
  if metadata_path is not None:
    header = mpm_io.read_header(h5_path)
    bounds = np.asarray(header["bounds"]).tolist()
    mpm_io.write_json(metadata_path, {
        "bounds": bounds,
        "sequence_length": int(header["sequence_length"]),
        "default_connectivity_radius": float(header["connectivity_radius"]),
        "dim": int(header["dim"]),
        "dt": float(header["frame_dt"]),
        **{k: np.asarray(header[k]).tolist()
           for k in ("vel_mean", "vel_std", "acc_mean", "acc_std")},
    })
  return len(entries)


def _placeholder_scene(bounds, dt: float, name: str) -> scene_lib.Scene:
  width, height = float(bounds[0][1]), float(bounds[1][1])
  return scene_lib.Scene.from_dict({
      "name": name,
      "domain": {"width": width, "height": height},
      "ramp": {"kind": "polyline", "points": [[0.0, 0.0], [width, 0.0]]},
      "granular": {"box": [0.0, 0.0, width, height],
                   "spacing": min(width, height) / 8},
      "frame_dt": dt,
  })


def import_npz(npz_path: str, metadata_path: str, h5_path: str) -> int:
  """Converts an npz split with its metadata.json to our format.

  Returns:
    The number of trajectories written.

  Raises:
    mpm_io.FormatError: a missing key, a non-2D dataset, or bad shapes.
  """
  try:
    with open(metadata_path) as f:
      meta = json.load(f)
    bounds, dt = meta["bounds"], float(meta["dt"])
    stats = {k: np.asarray(meta[k], np.float64)
             for k in ("vel_mean", "vel_std", "acc_mean", "acc_std")}
  except (OSError, json.JSONDecodeError, KeyError) as e:
    raise mpm_io.FormatError(f"{metadata_path}: not a GNS metadata file "
                             f"({e!r})") from e
  if int(meta.get("dim", 2)) != 2 or np.asarray(bounds).shape != (2, 2):
    raise mpm_io.FormatError(f"{metadata_path}: only 2D datasets are "
                             f"supported; dim={meta.get('dim')}, "
                             f"bounds={bounds}")
  radius = float(meta.get("default_connectivity_radius",
                          mpm_io.DEFAULT_CONNECTIVITY_RADIUS))
  base = os.path.basename(npz_path)
  trajectories = []
  with np.load(npz_path, allow_pickle=True) as data:
    for i, key in enumerate(sorted(data.keys(),
                                   key=lambda k: int(k.rsplit("_", 1)[-1]))):
      positions, types = data[key][0], np.asarray(data[key][1])
      positions = np.asarray(positions, np.float32)
      if positions.ndim != 3 or positions.shape[1:] != (len(types), 2):
        raise mpm_io.FormatError(f"{npz_path}:{key}: positions "
                                 f"{positions.shape} do not match "
                                 f"{len(types)} particle types in 2D")
      still = np.all(positions == positions[:1], axis=(0, 2))
      fixed = (types == KINEMATIC_TYPE) & still
      trajectories.append(mpm_io.Trajectory(
          positions=positions[:, ~fixed],
          boundary_positions=positions[0, fixed],
          boundary_type=np.full(int(fixed.sum()), geometry.RAMP_TYPE,
                                np.int32),
          scene=_placeholder_scene(bounds, dt, f"imported/{base}/{i}"),
          particle_type=types[~fixed].astype(np.int32)))
  mpm_io.write_trajectories(h5_path, trajectories, stats=stats,
                            connectivity_radius=radius)
  return len(trajectories)
