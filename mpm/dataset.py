"""The paper's dataset: scene plans, resumable generation, verification.

A dataset directory holds ``train.h5``, ``test.h5`` (``mpm.io`` format) and
``metadata.json`` (the keys of DeepMind's and geoelements' GNS datasets plus
our own). Generation writes each finished trajectory atomically to
``parts/<split>_<index>.h5``; once all exist they are assembled into the split
files (normalisation statistics from the training split only) and
``metadata.json`` is written last, marking the dataset complete. A run killed
at any moment is resumed by running it again: finished parts are kept, half-
written temporary files are discarded, nothing is duplicated.

Worker processes die with the generator (even on kill -9), so none is left
writing parts after it. One generator runs per directory at a time: it
holds an exclusive ``flock`` on the directory, and a second one fails at
once. Temp files carry their writer's host and pid, and a rerun removes
only this host's whose writer is gone (the machinery: ``mpm.workers``).

Sharded (``generate(..., shard=Shard(i, N))``, one process per share, on one
host or several sharing a filesystem): share i is the trajectories k of the
plan with k mod N = i; each shard holds a shared lock on the directory and
an exclusive one on its share, writes only its parts, and ``spec.json`` is
written once (a hard link: first writer wins, the others check it). One
``assemble_parts`` afterwards writes what an unsharded run writes. Sharing
a filesystem is the only assumption: the results do not depend on the locks
(two processes on one share write the same parts, each atomically).

The test split is planned so that the paper's breakdowns can be computed:
obstacle count (0, 1, 2), particle count (700, 1000, 1500 at the paper's
spacing), obstacle shape (semicircle, rectangle, and the triangle, which
training never sees) and rectangle position (x = 0.6, 1.0, 1.3). Each test
trajectory records its ``group`` in the scene name.
"""

import dataclasses
import functools
import json
import os
import shutil
from typing import Callable, Sequence

import numpy as np

from mpm import io as mpm_io
from mpm import sampler
from mpm import scene as scene_lib
from mpm import simulation
from mpm import workers as workers_lib

PAPER_SPACING = 0.005
TEST_PARTICLES = (700, 1000, 1500)
# The test plan cycles through these groups: (tag, shapes, obstacle count,
# fixed x of the obstacle or None).
TEST_GROUPS = (
    ("none", (), 0, None),
    ("semicircle", ("semicircle",), 1, None),
    ("rectangle_x0.6", ("rectangle",), 1, 0.6),
    ("rectangle_x1.0", ("rectangle",), 1, 1.0),
    ("rectangle_x1.3", ("rectangle",), 1, 1.3),
    ("triangle", ("triangle",), 1, None),
    ("two", ("semicircle", "rectangle", "triangle"), 2, None),
)
_TEST_SEED_OFFSET = 1_000_000


@dataclasses.dataclass(frozen=True)
class DatasetSpec:
  """What to generate (plain values: a config's ``dataset`` block).

  Attributes:
    num_train, num_test: trajectories per split.
    num_frames: frames per trajectory (frame 0 is the initial state).
    seed: base seed; trajectory i of a split uses a seed derived from it.
    spacing: particle spacing (m); the grid spacing is twice that, and the
      paper's particle counts scale with (0.005 / spacing)^2.
    connectivity_radius: written to the metadata for the learned simulator.
    rheology: the sand's, ``mpm.scene.RHEOLOGIES`` (mu(I) with its
      defaults: docs/physics.md).
  """
  num_train: int = 1000
  num_test: int = 100
  num_frames: int = 600
  seed: int = 0
  spacing: float = PAPER_SPACING
  connectivity_radius: float = 0.015
  rheology: str = "drucker_prager"

  def __post_init__(self):
    if self.rheology not in scene_lib.RHEOLOGIES:
      raise scene_lib.InputError(
          f"dataset.rheology = {self.rheology!r}; allowed: one of "
          f"{list(scene_lib.RHEOLOGIES)}")
    # Both splits are written, and the statistics need 3 frames.
    for key, lo in (("num_train", 1), ("num_test", 1), ("num_frames", 3)):
      value = getattr(self, key)
      if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise scene_lib.InputError(f"dataset.{key} = {value!r}; allowed: an "
                                   f"integer >= {lo}")
    for key in ("spacing", "connectivity_radius"):
      if not getattr(self, key) > 0:
        raise scene_lib.InputError(f"dataset.{key} = {getattr(self, key)!r};"
                                   " allowed: > 0")

  def particles(self, n: int) -> int:
    """A paper particle count at this spacing."""
    return max(1, int(round(n * (PAPER_SPACING / self.spacing)**2)))


@dataclasses.dataclass(frozen=True)
class PlannedScene:
  split: str
  index: int
  seed: int
  scene: scene_lib.Scene

  @property
  def part_name(self) -> str:
    return f"{self.split}_{self.index:05d}.h5"


def _scene(spec: DatasetSpec, seed: int, name: str, **kwargs):
  scene = sampler.sample_scene(seed, name=name, num_frames=spec.num_frames,
                               spacing=spec.spacing, **kwargs)
  return (scene if spec.rheology == "drucker_prager" else
          scene_lib.with_rheology(scene, spec.rheology))


def plan(spec: DatasetSpec) -> list[PlannedScene]:
  """Every scene of the dataset, deterministic from ``spec``."""
  lo, hi = (spec.particles(n) for n in sampler.PARTICLE_RANGE)
  scenes = []
  for i in range(spec.num_train):
    seed = spec.seed + i
    n = int(np.random.default_rng([seed, 1]).integers(lo, hi + 1))
    scenes.append(PlannedScene("train", i, seed, _scene(
        spec, seed, f"train/{i:05d}", num_particles=n)))
  for i in range(spec.num_test):
    seed = spec.seed + _TEST_SEED_OFFSET + i
    tag, shapes, count, x = TEST_GROUPS[i % len(TEST_GROUPS)]
    n = spec.particles(TEST_PARTICLES[i % len(TEST_PARTICLES)])
    scenes.append(PlannedScene("test", i, seed, _scene(
        spec, seed, f"test/{i:05d}/{tag}", num_particles=n,
        num_obstacles=count, shapes=shapes or sampler.TRAIN_SHAPES,
        obstacle_x=None if x is None else [x])))
  return scenes


def scene_key(scene: scene_lib.Scene) -> str:
  """The scene apart from its name, as canonical JSON: two planned scenes
  with the same key are the same simulation (the solver is deterministic),
  so their trajectories are equal."""
  d = scene.to_dict()
  d.pop("name", None)
  return json.dumps(d, sort_keys=True)


@dataclasses.dataclass(frozen=True)
class Overlap:
  """Repeated scenes in a plan (``overlap``).

  Attributes:
    distinct_train, distinct_test: distinct scenes per split.
    test_in_train: names of test scenes equal to a training scene.
    test_repeats: names of test scenes equal to an earlier test scene
      (and to no training scene).
  """
  distinct_train: int
  distinct_test: int
  test_in_train: tuple[str, ...]
  test_repeats: tuple[str, ...]

  def seen(self, name: str) -> bool:
    """Whether a test scene's trajectory is not new: in training, or a
    repeat of an earlier test scene."""
    return name in self.test_in_train or name in self.test_repeats


def overlap(plans: Sequence[PlannedScene]) -> Overlap:
  """The scenes a plan repeats. Without obstacles a scene is set by its
  particle count alone, and counts map onto few sand boxes, so most such
  scenes repeat (docs/dataset.md)."""
  train = {scene_key(p.scene) for p in plans if p.split == "train"}
  test_seen: set[str] = set()
  in_train, repeats = [], []
  for p in plans:
    if p.split != "test":
      continue
    key = scene_key(p.scene)
    if key in train:
      in_train.append(p.scene.name)
    elif key in test_seen:
      repeats.append(p.scene.name)
    test_seen.add(key)
  return Overlap(len(train), len(test_seen), tuple(in_train), tuple(repeats))


def group_of(scene_name: str) -> str:
  """The test group tag of a planned scene's name ('' for training)."""
  parts = scene_name.split("/")
  return parts[2] if len(parts) > 2 else ""


# ------------------------------------------------------------- generation ---


def _simulate_part(item: PlannedScene, parts_dir: str) -> float:
  """Simulates one planned scene and writes its part file atomically."""
  return _write_part(item, simulation.simulate(item.scene), parts_dir)


def _write_part(item: PlannedScene, result, parts_dir: str) -> float:
  mpm_io.write_trajectories(os.path.join(parts_dir, item.part_name),
                            [mpm_io.Trajectory.from_result(result, item.seed)])
  return result.wall_time_s


def _part_done(item: PlannedScene, parts_dir: str) -> bool:
  """Whether ``item``'s part is written, whole (else it is redone).

  Raises:
    InputError: the part holds another scene than the planned one: made
      with another config (or by a version that kept no spec.json), so
      resuming would mix two datasets.
  """
  path = os.path.join(parts_dir, item.part_name)
  try:
    with mpm_io.open_file(path) as f:
      if len(f.keys()) != 1:
        return False
      stored = next(iter(f.values())).attrs.get("scene")
  except mpm_io.FormatError:
    return False
  if stored is None:
    return False
  stored = scene_lib.Scene.from_json(stored)
  if stored != item.scene:
    raise scene_lib.InputError(
        f"{path} holds another scene than this config plans for "
        f"{item.part_name} ({stored.name!r} "
        "simulated with other values): the parts in "
        f"{parts_dir} were made with another config; use another "
        "directory or the same config")
  return True


_SPEC_FILE = "spec.json"


def _differences(stored: dict, spec: DatasetSpec) -> list[str]:
  current = dataclasses.asdict(spec)
  # A key added since the dataset was made has its default there.
  made = {f.name: stored.get(f.name, f.default)
          for f in dataclasses.fields(DatasetSpec)}
  return [f"{k} {made[k]!r} (this config: {current[k]!r})"
          for k in current if made[k] != current[k]]


def check_target(spec: DatasetSpec, out_dir: str) -> None:
  """Refuses ``out_dir`` if it holds a dataset, or the parts of one, made
  with another spec (resuming or reusing it would mix or misreport them).

  Raises:
    InputError: naming the directory and the differing values.
  """
  for name, what in (("metadata.json", "a dataset"),
                     (os.path.join("parts", _SPEC_FILE),
                      "an unfinished dataset")):
    path = os.path.join(out_dir, name)
    if not os.path.exists(path):
      continue
    stored = mpm_io.read_json(path)
    stored = stored.get("spec", {}) if name == "metadata.json" else stored
    differences = _differences(stored, spec)
    if differences:
      raise scene_lib.InputError(
          f"{out_dir} holds {what} of another config: its "
          f"{', '.join(differences)}; use another directory or the same "
          "config")


def _exclusive(out_dir: str):
  """Holds an exclusive lock on the directory ``out_dir``: no other
  generator, sharded or not, runs on it meanwhile."""
  return workers_lib.locked(out_dir, f"{out_dir}: another generator is running on this "
                 "directory; wait for it (or kill it) and rerun")


@dataclasses.dataclass(frozen=True)
class Shard:
  """Share ``index`` of ``count`` of a dataset's trajectories (``i/N``).

  Trajectory k of ``plan`` (train then test) belongs to share k mod N, so
  the shares are disjoint, cover the plan, and mix both splits evenly.
  """
  index: int
  count: int

  def __post_init__(self):
    if (isinstance(self.count, bool) or not isinstance(self.count, int) or
        self.count < 1 or not isinstance(self.index, int) or
        not 0 <= self.index < self.count):
      raise scene_lib.InputError(
          f"--shard={self.index}/{self.count}; allowed: i/N with integers "
          "N >= 1 and 0 <= i < N")

  @classmethod
  def parse(cls, text: str) -> "Shard":
    """``"i/N"`` -> Shard(i, N); InputError naming the text otherwise."""
    index, sep, count = text.strip().partition("/")
    if not sep or not index.strip().isdigit() or not count.strip().isdigit():
      raise scene_lib.InputError(
          f"--shard={text}; allowed: i/N with integers N >= 1 and "
          "0 <= i < N (e.g. 0/4)")
    return cls(int(index), int(count))

  def take(self, items: Sequence[PlannedScene]) -> list[PlannedScene]:
    return [it for k, it in enumerate(items) if k % self.count == self.index]

  def __str__(self):
    return f"{self.index}/{self.count}"


def generate(spec: DatasetSpec, out_dir: str, *, workers: int = 2,
             progress: Callable[[int, int, float], None] | None = None,
             compilation_cache: str | None = None,
             shard: Shard | None = None, batch: int = 1) -> dict:
  """Generates (or finishes) the dataset in ``out_dir``.

  Args:
    workers: processes simulating in parallel (1: in this process).
    batch: scenes per vmapped call (``simulate_batch``; workers = 1): for
      an accelerator; within 1e-6 m of one at a time, not bit for bit.
    compilation_cache: persistent compilation cache for worker processes.
    progress: called as progress(done, total, wall_time_s) after each
      trajectory (also for parts found finished from an earlier run).
    shard: simulate only this share of the trajectories and stop, leaving
      the parts for ``assemble_parts`` (other shares may run meanwhile, in
      other processes or on other hosts sharing the filesystem).

  Returns:
    The metadata written (or found, if the dataset is complete); for a
    shard, {"shard": "i/N", "parts": its part count} (or the metadata if
    the dataset is already complete).

  Raises:
    InputError: ``out_dir`` holds a dataset or parts of another spec.
    workers_lib.GeneratorBusyError: another generator is running on ``out_dir`` (for
      a shard: one that is not sharded, or on the same shard).
  """
  if batch < 1 or (batch > 1 and workers > 1):
    raise scene_lib.InputError(
        f"batch={batch} with workers={workers}; allowed: batch >= 1, and "
        "batch > 1 only with workers = 1 (one process drives the batches)")
  check_target(spec, out_dir)
  meta_path = os.path.join(out_dir, "metadata.json")
  if os.path.exists(meta_path):
    return mpm_io.read_json(meta_path)
  os.makedirs(out_dir, exist_ok=True)
  if shard is not None:
    return _generate_shard(spec, out_dir, (workers, batch), progress,
                           compilation_cache, shard)
  with _exclusive(out_dir):
    if os.path.exists(meta_path):  # finished before we took the lock
      return mpm_io.read_json(meta_path)
    return _generate(spec, out_dir, (workers, batch), progress,
                     compilation_cache)


def _write_spec_once(spec: DatasetSpec, parts_dir: str) -> None:
  """Writes ``parts/spec.json`` unless there is one; with several shards
  starting at once the first writer wins (a hard link is atomic and fails
  if the name exists) and the others check that theirs is the same."""
  path = os.path.join(parts_dir, _SPEC_FILE)
  if not os.path.exists(path):
    tmp = mpm_io.temp_path(path)
    mpm_io.write_text(tmp, json.dumps(dataclasses.asdict(spec), indent=2))
    try:
      os.link(tmp, path)
    except FileExistsError:
      pass
    finally:
      os.remove(tmp)
  check_target(spec, os.path.dirname(parts_dir))


def _simulate_all(todo, parts_dir, parallel, compilation_cache, on_done):
  """Simulates ``todo`` into parts, ``on_done(wall)`` after each; parallel
  = (processes, batch): vmapped batches in this process if batch > 1."""
  workers, batch = parallel
  if batch > 1:
    for i in range(0, len(todo), batch):
      chunk = todo[i:i + batch]
      results = simulation.simulate_batch([it.scene for it in chunk],
                                          max_batch=batch)
      for item, result in zip(chunk, results):
        on_done(_write_part(item, result, parts_dir))
    return
  if workers <= 1 or len(todo) <= 1:
    for it in todo:
      on_done(_simulate_part(it, parts_dir))
    return
  workers_lib.map_in_processes(
      functools.partial(_simulate_part, parts_dir=parts_dir), todo, workers,
      compilation_cache, on_done)


def _generate(spec, out_dir, parallel, progress, compilation_cache) -> dict:
  parts_dir = os.path.join(out_dir, "parts")
  os.makedirs(parts_dir, exist_ok=True)
  workers_lib.remove_stale_temps(parts_dir)
  items = plan(spec)
  _simulate_items(spec, items, parts_dir, parallel, progress,
                  compilation_cache)
  return assemble(spec, out_dir, items)


def _simulate_items(spec, items, parts_dir, parallel, progress,
                    compilation_cache) -> None:
  # Checked before spec.json is written: parts of another config (say, from
  # a version that kept no spec.json) are refused, not adopted.
  todo = [it for it in items if not _part_done(it, parts_dir)]
  _write_spec_once(spec, parts_dir)
  done = len(items) - len(todo)
  if progress is not None:
    progress(done, len(items), 0.0)

  def on_done(wall):
    nonlocal done
    done += 1
    if progress is not None:
      progress(done, len(items), wall)

  _simulate_all(todo, parts_dir, parallel, compilation_cache, on_done)


def _generate_shard(spec, out_dir, parallel, progress, compilation_cache,
                    shard: Shard) -> dict:
  # Shards share the directory (a shared lock: an unsharded generator or an
  # assembly waits for all of them) and each holds its own share.
  with workers_lib.locked(out_dir, f"{out_dir}: a generator that is not sharded (or "
               "an assembly) is running on this directory; wait for it and "
               "rerun", shared=True):
    parts_dir = os.path.join(out_dir, "parts")
    os.makedirs(parts_dir, exist_ok=True)
    lock = os.path.join(parts_dir,
                        f".shard-{shard.index}-of-{shard.count}.lock")
    with workers_lib.locked(lock, f"{out_dir}: shard {shard} is already being "
                 "generated by another process; wait for it (or kill it) "
                 "and rerun"):
      workers_lib.remove_stale_temps(parts_dir)
      items = shard.take(plan(spec))
      _simulate_items(spec, items, parts_dir, parallel, progress,
                      compilation_cache)
  return {"shard": str(shard), "parts": len(items)}


def assemble_parts(spec: DatasetSpec, out_dir: str) -> dict:
  """Assembles the parts that shards (``generate(..., shard=...)``) wrote
  into the dataset, as an unsharded run would have.

  Returns:
    The metadata written (or found, if the dataset is complete).

  Raises:
    InputError: parts are missing (naming how many and the first ones), or
      ``out_dir`` holds a dataset or parts of another spec.
    workers_lib.GeneratorBusyError: a generator is still running on ``out_dir``.
  """
  check_target(spec, out_dir)
  meta_path = os.path.join(out_dir, "metadata.json")
  if os.path.exists(meta_path):
    return mpm_io.read_json(meta_path)
  parts_dir = os.path.join(out_dir, "parts")
  if not os.path.isdir(parts_dir):
    raise scene_lib.InputError(
        f"--assemble: {out_dir} holds no parts; generate them first (with "
        "--shard=i/N for each i)")
  with workers_lib.locked(out_dir, f"{out_dir}: a generator is still running on this "
               "directory; wait for every shard to finish, then assemble"):
    if os.path.exists(meta_path):
      return mpm_io.read_json(meta_path)
    items = plan(spec)
    missing = [it.part_name for it in items
               if not _part_done(it, parts_dir)]
    if missing:
      raise scene_lib.InputError(
          f"--assemble: {len(missing)} of {len(items)} parts are missing in "
          f"{parts_dir} (first: {', '.join(missing[:3])}); run the shards "
          "that hold them (or rerun any shard: finished parts are kept)")
    return assemble(spec, out_dir, items)


def _read_part(parts_dir: str, item: PlannedScene) -> mpm_io.Trajectory:
  (trajectory,) = mpm_io.read_trajectories(
      os.path.join(parts_dir, item.part_name))
  return trajectory


def assemble(spec: DatasetSpec, out_dir: str,
             items: Sequence[PlannedScene]) -> dict:
  """Writes the split files and metadata from finished parts; removes them."""
  parts_dir = os.path.join(out_dir, "parts")
  train = [it for it in items if it.split == "train"]
  stats = mpm_io.finite_difference_stats(
      _read_part(parts_dir, it).positions for it in train)
  wall_time = {}
  for split in ("train", "test"):
    members = [it for it in items if it.split == split]
    wall_time[split] = sum(mpm_io.write_split(
        os.path.join(out_dir, f"{split}.h5"),
        (_read_part(parts_dir, it) for it in members), stats=stats,
        connectivity_radius=spec.connectivity_radius))
  first = items[0].scene
  metadata = {
      # DeepMind / geoelements GNS keys
      "bounds": [[0.0, first.domain.width], [0.0, first.domain.height]],
      "sequence_length": spec.num_frames,
      "default_connectivity_radius": spec.connectivity_radius,
      "dim": 2,
      "dt": first.frame_dt,
      **{k: [float(v) for v in stats[k]]
         for k in ("vel_mean", "vel_std", "acc_mean", "acc_std")},
      # ours
      "format_version": mpm_io.FORMAT_VERSION,
      "num_train": spec.num_train,
      "num_test": spec.num_test,
      "spec": dataclasses.asdict(spec),
      "wall_time_s": wall_time,
  }
  mpm_io.write_json(os.path.join(out_dir, "metadata.json"), metadata)
  shutil.rmtree(parts_dir)
  return metadata


# ----------------------------------------------------------- verification ---


def load_spec(out_dir: str) -> DatasetSpec:
  """The spec a finished dataset was generated from (its metadata)."""
  path = os.path.join(out_dir, "metadata.json")
  if not os.path.exists(path):
    raise mpm_io.FormatError(f"{path}: missing; the dataset is incomplete "
                             "(rerun the generation to finish it)")
  try:
    return DatasetSpec(**mpm_io.read_json(path)["spec"])
  except (json.JSONDecodeError, KeyError, TypeError) as e:
    raise mpm_io.FormatError(f"{path}: not a dataset metadata file ({e})"
                             ) from e


def verify(out_dir: str, *, reproduce: int = 2,
           reproduce_frames: int = 10) -> list[str]:
  """Checks a finished dataset; returns the problems found (empty: sound).

  Every trajectory: readable, the planned shape [num_frames, N, 2], finite,
  its scene the one its seed plans. For ``reproduce`` trajectories per split
  the first ``reproduce_frames`` frames are simulated again and compared.
  """
  try:
    spec = load_spec(out_dir)
  except mpm_io.FormatError as e:
    return [str(e)]
  items = {(it.split, it.index): it for it in plan(spec)}
  reproduce_frames = min(reproduce_frames, spec.num_frames)
  problems = []
  for split, count in (("train", spec.num_train), ("test", spec.num_test)):
    path = os.path.join(out_dir, f"{split}.h5")
    try:
      with mpm_io.open_file(path) as f:
        names = sorted(f.keys())
        if len(names) != count:
          problems.append(f"{path}: {len(names)} trajectories, expected "
                          f"{count}")
        for i, name in enumerate(names):
          where = f"{path}:{name}"
          try:
            t = mpm_io.read_group(f[name])
          except mpm_io.FormatError as e:
            problems.append(str(e))
            continue
          item = items.get((split, i))
          if item is None or t.scene != item.scene or t.seed != item.seed:
            problems.append(f"{where}: scene or seed differs from the plan "
                            f"for {split} trajectory {i}")
            continue
          expected = (spec.num_frames, item.scene.granular.num_particles, 2)
          if t.positions.shape != expected:
            problems.append(f"{where}: positions shape {t.positions.shape}, "
                            f"expected {expected}")
          elif i < reproduce:
            scene = dataclasses.replace(item.scene,
                                        num_frames=reproduce_frames)
            again = simulation.simulate(scene).positions
            err = float(np.max(np.abs(again - t.positions[:reproduce_frames])))
            if err > 1e-5:
              problems.append(f"{where}: seed {t.seed} does not reproduce "
                              f"the first {reproduce_frames} frames (max "
                              f"difference {err:.2e} m)")
    except mpm_io.FormatError as e:
      problems.append(str(e))
  return problems
