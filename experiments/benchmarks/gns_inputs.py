"""The GNS benchmark's inputs: windows of C + 1 frames and their graphs.

* the shared sand block window (``load_sand_block``): 1000 sand particles,
  the graph public GNS implementations were timed on (24,930 directed edges
  at R = 0.015 m, self-pairs included; checked). It is not part of the
  repository: the benchmark takes its directory as ``--sand_block_dir``;
* the paper scene (``make_paper_scene``), simulated with ``mpm.simulate``,
  with its boundary (ramp and obstacle) particles as static nodes.

The model sees the solids through its scene's signed distance field
(``mpm.SDFGrid``, node features [N, 2 (C - 1) + 3]): the paper scene's own,
and for the sand block, which has no scene of its own, that of the paper's
default scene ``scenes.PAPER_SCENE``. The grids are sampled at R / 6, the
configs' default ``model.sdf_spacing``.

Both graphs are computed before any clock starts and hold exactly their
edges (no capacity padding); the neighbour list's padded form rides along
for the row that times it.
"""

import dataclasses
import json
import os

import jax.numpy as jnp
import numpy as np

import mpm
from experiments.benchmarks import scenes
from gnsjax import data
from gnsjax import features
from gnsjax import graph
from gnsjax import rollout as rollout_lib
from gnsjax import simulator
from mpm import geometry
from mpm import io as mpm_io

# The shared benchmark input: a directory (--sand_block_dir) holding these
# two files and the README that quotes the peers' times.
SAND_BLOCK_NPZ = "sand_block_window.npz"
SAND_BLOCK_METADATA = "sand_block_metadata.json"
SAND_BLOCK_README = "README.md"
SAND_BLOCK_EDGES = 24_930  # at R = 0.015 m, self-pairs included
# C, input frames per window (as the configs' input_frames and the peers).
INPUT_FRAMES = 6
# SDF grid spacing per connectivity radius: the configs' default
# (``model.sdf_spacing`` None: R / 6, ``gnsjax.train``).
SDF_SPACING_PER_RADIUS = 1 / 6


def sdf_spacing(radius: float) -> float:
  """The SDF grid spacing (m) of a model of connectivity radius R (m) whose
  config leaves ``model.sdf_spacing`` unset."""
  return radius * SDF_SPACING_PER_RADIUS


def paper_scene(num_frames: int = 1) -> mpm.Scene:
  """``scenes.PAPER_SCENE`` as an ``mpm.Scene`` of ``num_frames`` frames."""
  return mpm.Scene.from_dict({**scenes.PAPER_SCENE,
                              "num_frames": num_frames})


@dataclasses.dataclass(frozen=True)
class BenchGraph:
  """One window and its radius graph.

  Attributes:
    name: scene name.
    positions: float32 [C + 1, N, 2] (m): C inputs, then the target.
    particle_type: int32 [N]; moving: bool [N].
    stats: normalisation statistics; bounds: [2, 2] (m); radius: R (m).
    scene: the scene whose solids the model sees; solids: its SDF grid at
      ``sdf_spacing(radius)``.
    senders, receivers: int32 [E], the graph's edges (no padding).
    padded_senders, padded_receivers: int32 [capacity], the neighbour list's
      edges with padding entries equal to N (as rollouts use them).
    info: what to record about the scene.
  """
  name: str
  positions: np.ndarray
  particle_type: np.ndarray
  moving: np.ndarray
  stats: features.Stats
  bounds: np.ndarray
  radius: float
  scene: mpm.Scene
  solids: geometry.SDFGrid
  senders: np.ndarray
  receivers: np.ndarray
  padded_senders: np.ndarray
  padded_receivers: np.ndarray
  info: dict

  @property
  def n_nodes(self) -> int:
    return int(self.positions.shape[1])

  @property
  def n_edges(self) -> int:
    return int(self.senders.shape[0])

  @property
  def context(self) -> simulator.Context:
    return simulator.Context(
        features.Stats(*(jnp.asarray(s, jnp.float32) for s in self.stats)))

  def solids_at(self, spacing: float | None = None) -> geometry.SDFGrid:
    """The scene's SDF grid at ``spacing`` (m; default: ``solids``')."""
    if spacing is None or spacing == self.solids.spacing:
      return self.solids
    return data.solids_of(self.scene, spacing)

  @property
  def sdf_info(self) -> dict:
    """What to record about the solids the model sees."""
    return {"sdf_scene": self.scene.name,
            "sdf_spacing": float(self.solids.spacing),
            "sdf_grid": list(self.solids.values.shape[:2])}


def _radius_graph(last: np.ndarray, bounds: np.ndarray, radius: float):
  """(senders, receivers) without and with padding, from ``gnsjax.graph``."""
  spec = graph.GraphSpec(radius, tuple(map(tuple, np.asarray(
      bounds, np.float64).tolist())))
  n = last.shape[0]
  nbrs = graph.allocate(spec, jnp.asarray(last))
  if bool(nbrs.did_buffer_overflow):
    raise RuntimeError("neighbour list overflowed at allocation")
  senders, receivers = (np.asarray(a) for a in graph.edges(nbrs, n))
  real = senders < n
  return senders[real], receivers[real], senders, receivers


def sand_block_files(directory: str) -> list[str]:
  """The input files of the sand block window in ``directory``.

  Raises:
    FileNotFoundError: a missing input file (named).
  """
  paths = [os.path.join(directory, f) for f in (SAND_BLOCK_NPZ,
                                                 SAND_BLOCK_METADATA)]
  for path in paths:
    if not os.path.exists(path):
      raise FileNotFoundError(f"{path}: missing benchmark input (the shared "
                              "sand block window; see --sand_block_dir)")
  return paths


def load_sand_block(directory: str) -> BenchGraph:
  """The shared sand block window, its metadata and graph; the solids the
  model sees are the paper scene's (``scenes.PAPER_SCENE``).

  Args:
    directory: holds ``sand_block_window.npz`` (positions float32
      [C + 1, N, 2] in m, particle_type int32 [N]) and
      ``sand_block_metadata.json`` (bounds, radius, statistics).

  Raises:
    FileNotFoundError: a missing input file (named).
    RuntimeError: the graph does not have the 24,930 edges the peers had.
  """
  npz, meta_path = sand_block_files(directory)
  with np.load(npz) as d:
    positions = np.asarray(d["positions"], np.float32)
    types = np.asarray(d["particle_type"], np.int32)
  with open(meta_path) as f:
    meta = json.load(f)
  if positions.shape[0] != INPUT_FRAMES + 1:
    raise ValueError(f"{npz}: positions {positions.shape}; want "
                     f"[{INPUT_FRAMES + 1}, N, 2]")
  radius = float(meta["default_connectivity_radius"])
  bounds = np.asarray(meta["bounds"], np.float32)
  stats = features.Stats(*(np.asarray(meta[k], np.float32) for k in
                           ("vel_mean", "vel_std", "acc_mean", "acc_std")))
  senders, receivers, ps, pr = _radius_graph(positions[INPUT_FRAMES - 1],
                                             bounds, radius)
  if len(senders) != SAND_BLOCK_EDGES:
    raise RuntimeError(
        f"sand block graph at R = {radius}: {len(senders)} edges, want "
        f"{SAND_BLOCK_EDGES} (the graph the peers were timed on)")
  moving = ~np.isin(types, mpm.KINEMATIC_TYPES)
  scene = paper_scene()
  return BenchGraph(
      "sand_block", positions, types, moving, stats, bounds, radius, scene,
      data.solids_of(scene, sdf_spacing(radius)), senders, receivers, ps, pr,
      {"source": npz, "n_particles": int(positions.shape[1]),
       "n_moving": int(moving.sum()), "n_boundary": 0,
       "edges_checked": SAND_BLOCK_EDGES})


def make_paper_scene(scene_frames: int, window_start: int,
                     radius: float = 0.015) -> BenchGraph:
  """Frames ``window_start``.. of the paper scene simulated for
  ``scene_frames`` frames, with all of its boundary particles as static
  nodes (``rollout.trajectory_nodes``), its SDF grid, and statistics from
  its finite differences; the graph at ``radius`` (m)."""
  scene = paper_scene(scene_frames)
  result = mpm.simulate(scene)
  t0 = window_start
  window = result.positions[t0:t0 + INPUT_FRAMES + 1]
  if window.shape[0] != INPUT_FRAMES + 1:
    raise ValueError(f"paper scene: {scene_frames} frames hold no "
                     f"window of {INPUT_FRAMES + 1} from frame {t0}")
  traj = mpm_io.Trajectory.from_result(result)
  traj = dataclasses.replace(traj, positions=window)
  # C + 1 frames at stride 1: the inputs, then the target.
  nodes = rollout_lib.trajectory_nodes(traj, INPUT_FRAMES + 1, 1,
                                       boundary=True,
                                       sdf_spacing=sdf_spacing(radius))
  positions, types, moving = nodes.window, nodes.types, nodes.moving
  fd = mpm_io.finite_difference_stats([result.positions])
  stats = features.Stats(*(np.asarray(fd[k], np.float32) for k in
                           features.Stats._fields))
  bounds = np.array([[0.0, scene.domain.width], [0.0, scene.domain.height]],
                    np.float32)
  senders, receivers, ps, pr = _radius_graph(positions[INPUT_FRAMES - 1],
                                             bounds, radius)
  n_sand = int(result.positions.shape[1])
  return BenchGraph(
      "paper_scene", positions.astype(np.float32), types, moving, stats,
      bounds, radius, scene, nodes.solids, senders, receivers, ps, pr,
      {"scene": scene.to_dict(),
       "frames": [t0, t0 + INPUT_FRAMES], "n_particles": n_sand,
       "n_moving": int(moving.sum()),
       "n_boundary": int(positions.shape[1]) - n_sand,
       "stats": "finite differences of the simulated trajectory "
                f"({scene_frames} frames)"})
