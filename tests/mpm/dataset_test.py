"""Tests for `mpm.dataset` and `mpm.io`: generation, resume, files, errors."""

import csv
import dataclasses
import glob
import os
import signal
import subprocess
import sys
import tempfile
import time

from absl.testing import absltest
import h5py
import numpy as np

import mpm
from mpm import dataset
from mpm import io as mpm_io
from mpm import workers as workers_lib

SPEC = dataset.DatasetSpec(num_train=3, num_test=2, num_frames=12, seed=5,
                           spacing=0.01, connectivity_radius=0.03)
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))


def _positions(path):
  return [t.positions for t in mpm_io.read_trajectories(path)]


def _children(pid):
  """Pids of the live child processes of ``pid`` (Linux /proc)."""
  out = set()
  for path in glob.glob(f"/proc/{pid}/task/*/children"):
    try:
      with open(path) as f:
        out.update(int(c) for c in f.read().split())
    except OSError:
      pass
  return out


def _alive(pid):
  """Whether ``pid`` runs (a zombie, dead but not reaped, does not)."""
  try:
    with open(f"/proc/{pid}/stat") as f:
      return f.read().rsplit(")", 1)[1].split()[0] != "Z"
  except OSError:
    return False


class DatasetTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls._tmp = tempfile.TemporaryDirectory()
    cls.ref = os.path.join(cls._tmp.name, "ref")
    dataset.generate(SPEC, cls.ref, workers=1)

  @classmethod
  def tearDownClass(cls):
    cls._tmp.cleanup()
    super().tearDownClass()

  def test_files_and_round_trip(self):
    self.assertEqual(sorted(os.listdir(self.ref)),
                     ["metadata.json", "test.h5", "train.h5"])
    train = list(mpm_io.read_trajectories(os.path.join(self.ref, "train.h5")))
    self.assertLen(train, SPEC.num_train)
    for item, t in zip(dataset.plan(SPEC), train):
      self.assertEqual(t.scene, item.scene)
      self.assertEqual(t.seed, item.seed)
      self.assertEqual(t.positions.shape,
                       (SPEC.num_frames, item.scene.granular.num_particles, 2))
      self.assertEqual(t.positions.dtype, np.float32)
      self.assertGreater(t.wall_time_s, 0)
    header = mpm_io.read_header(os.path.join(self.ref, "test.h5"))
    for key in ("format_version", "dim", "frame_dt", "bounds",
                "connectivity_radius", "sequence_length", "vel_mean",
                "vel_std", "acc_mean", "acc_std"):
      self.assertIn(key, header)
    self.assertEqual(header["sequence_length"], SPEC.num_frames)

  def test_statistics_from_training_split_only(self):
    train = _positions(os.path.join(self.ref, "train.h5"))
    v = np.concatenate([np.diff(x.astype(np.float64), axis=0).reshape(-1, 2)
                        for x in train])
    a = np.concatenate([np.diff(x.astype(np.float64), 2, axis=0).reshape(-1, 2)
                        for x in train])
    for split in ("train.h5", "test.h5"):
      header = mpm_io.read_header(os.path.join(self.ref, split))
      np.testing.assert_allclose(header["vel_mean"], v.mean(0), rtol=1e-6,
                                 atol=1e-12)
      np.testing.assert_allclose(header["vel_std"], v.std(0), rtol=1e-5)
      np.testing.assert_allclose(header["acc_mean"], a.mean(0), rtol=1e-5,
                                 atol=1e-12)
      np.testing.assert_allclose(header["acc_std"], a.std(0), rtol=1e-5)

  def test_test_split_covers_the_paper_breakdowns(self):
    spec = dataclasses.replace(SPEC, num_test=14)
    tests = [p for p in dataset.plan(spec) if p.split == "test"]
    groups = {dataset.group_of(p.scene.name) for p in tests}
    self.assertEqual(groups, {g[0] for g in dataset.TEST_GROUPS})
    counts = {len(p.scene.obstacles) for p in tests}
    self.assertEqual(counts, {0, 1, 2})
    particles = {p.scene.granular.num_particles for p in tests}
    self.assertEqual(particles, {spec.particles(n)
                                 for n in dataset.TEST_PARTICLES})
    rect_x = {o.x for p in tests for o in p.scene.obstacles
              if dataset.group_of(p.scene.name).startswith("rectangle")}
    self.assertEqual(rect_x, {0.6, 1.0, 1.3})
    train_shapes = {o.shape for p in dataset.plan(spec) if p.split == "train"
                    for o in p.scene.obstacles}
    self.assertNotIn("triangle", train_shapes)

  def test_deterministic(self):
    with tempfile.TemporaryDirectory() as d:
      dataset.generate(SPEC, d, workers=1)
      self._assert_equals_reference(d)

  def test_batched_equals_one_at_a_time_within_rounding(self):
    # Vmapped batches of 2 (the last of 1): the same scenes and seeds, the
    # positions within 1e-6 m of the one-at-a-time dataset's.
    with tempfile.TemporaryDirectory() as d:
      dataset.generate(SPEC, d, workers=1, batch=2)
      for split in ("train.h5", "test.h5"):
        got = list(mpm_io.read_trajectories(os.path.join(d, split)))
        ref = list(mpm_io.read_trajectories(os.path.join(self.ref, split)))
        self.assertEqual([(t.scene, t.seed) for t in got],
                         [(t.scene, t.seed) for t in ref])
        for a, b in zip(got, ref):
          np.testing.assert_allclose(a.positions, b.positions, atol=1e-6,
                                     rtol=0)
    with self.assertRaisesRegex(mpm.InputError, "batch=2 with workers=2"):
      dataset.generate(SPEC, "unused", workers=2, batch=2)
    with self.assertRaisesRegex(mpm.InputError, "batch=0"):
      dataset.generate(SPEC, "unused", workers=1, batch=0)
    self.assertFalse(os.path.exists("unused"))

  def _kill_after_first_part(self, d: str, workers: int) -> set[int]:
    """Runs a generator into ``d`` in a subprocess, SIGKILLs it once its
    first part is written, and returns the pids of the children seen."""
    script = (
        "import dataclasses, os, sys\n"
        "from mpm import dataset\n"
        f"spec = dataset.DatasetSpec(**{dataclasses.asdict(SPEC)!r})\n"
        f"dataset.generate(spec, sys.argv[1], workers={workers}, "
        "compilation_cache=os.environ.get('GNSJAX_CACHE_DIR'))\n")
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu")
    proc = subprocess.Popen([sys.executable, "-c", script, d], env=env,
                            stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    parts = os.path.join(d, "parts")
    deadline = time.time() + 120
    children = set()
    while time.time() < deadline and proc.poll() is None:
      children |= _children(proc.pid)
      if os.path.isdir(parts) and any(f.endswith(".h5")
                                      for f in os.listdir(parts)):
        break
      time.sleep(0.05)
    children |= _children(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    self.assertFalse(os.path.exists(os.path.join(d, "metadata.json")),
                     "the generator finished before it could be killed")
    return children

  def test_resume_after_kill_and_half_written_files(self):
    with tempfile.TemporaryDirectory() as d:
      self._kill_after_first_part(d, workers=1)
      parts = os.path.join(d, "parts")
      # What a kill mid-write leaves: a temporary file and (had the rename
      # not been atomic) a truncated part. Both must be redone.
      with open(os.path.join(parts, "test_00001.h5.tmp-12345"), "wb") as f:
        f.write(b"\x89HDF half written")
      with open(os.path.join(parts, "test_00000.h5"), "wb") as f:
        f.write(b"\x89HDF truncated")
      done_before = {f: os.path.getmtime(os.path.join(parts, f))
                     for f in os.listdir(parts) if f.startswith("train_")}
      calls = []
      dataset.generate(SPEC, d, workers=1,
                       progress=lambda done, total, wall: calls.append(done))
      self.assertEqual(calls[0], len(done_before),
                       "finished parts from the killed run were redone")
      self._assert_equals_reference(d)

  def _assert_equals_reference(self, d):
    """The dataset in ``d`` is the uninterrupted run's, bit for bit."""
    self.assertEqual(sorted(os.listdir(d)),
                     ["metadata.json", "test.h5", "train.h5"])
    for split in ("train.h5", "test.h5"):
      got, ref = (_positions(os.path.join(d, split)),
                  _positions(os.path.join(self.ref, split)))
      self.assertEqual(len(got), len(ref))
      for a, b in zip(got, ref):
        np.testing.assert_array_equal(a, b)

  def test_kill_9_takes_the_workers_along_and_the_rerun_finishes(self):
    with tempfile.TemporaryDirectory() as d:
      workers = self._kill_after_first_part(d, workers=2)
      self.assertGreaterEqual(len(workers), 2, "no worker processes seen")
      deadline = time.time() + 10
      while time.time() < deadline and any(map(_alive, workers)):
        time.sleep(0.05)
      self.assertEqual([p for p in workers if _alive(p)], [],
                       "workers outlived the killed generator")
      dataset.generate(SPEC, d, workers=2)
      self._assert_equals_reference(d)

  def test_two_shards_then_assembly_equal_one_process(self):
    # Two processes at once, each its share (as on two hosts sharing the
    # filesystem), then one assembly: the one-process dataset, bit for bit.
    with tempfile.TemporaryDirectory() as d:
      script = (
          "import dataclasses, os, sys\n"
          "from mpm import dataset\n"
          f"spec = dataset.DatasetSpec(**{dataclasses.asdict(SPEC)!r})\n"
          "dataset.generate(spec, sys.argv[1], workers=1, "
          "shard=dataset.Shard.parse(sys.argv[2]))\n")
      env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu")
      procs = [subprocess.Popen([sys.executable, "-c", script, d, f"{i}/2"],
                                env=env) for i in range(2)]
      self.assertEqual([p.wait(timeout=300) for p in procs], [0, 0])
      self.assertFalse(os.path.exists(os.path.join(d, "metadata.json")))
      names = sorted(f for f in os.listdir(os.path.join(d, "parts"))
                     if f.endswith(".h5"))
      self.assertLen(names, SPEC.num_train + SPEC.num_test)
      dataset.assemble_parts(SPEC, d)
      self._assert_same_files(d, self.ref)

  def _assert_same_files(self, d, ref):
    """Every array and attribute of the split files, and the metadata,
    equal bit for bit; only the measured wall times may differ."""
    self.assertEqual(sorted(os.listdir(d)), sorted(os.listdir(ref)))
    for split in ("train.h5", "test.h5"):
      with h5py.File(os.path.join(d, split)) as a, h5py.File(
          os.path.join(ref, split)) as b:
        for k in b.attrs:
          np.testing.assert_array_equal(a.attrs[k], b.attrs[k], err_msg=k)
        self.assertEqual(sorted(a.attrs), sorted(b.attrs))
        self.assertEqual(sorted(a), sorted(b))
        for name in b:
          self.assertEqual(sorted(a[name]), sorted(b[name]))
          for key in b[name]:
            x, y = a[name][key][()], b[name][key][()]
            self.assertEqual(x.dtype, y.dtype)
            self.assertEqual(x.tobytes(), y.tobytes(), f"{name}/{key}")
          self.assertEqual(sorted(a[name].attrs), sorted(b[name].attrs))
          for k in b[name].attrs:
            if k != "wall_time_s":
              self.assertEqual(a[name].attrs[k], b[name].attrs[k])
    got, want = (mpm_io.read_json(os.path.join(x, "metadata.json"))
                 for x in (d, ref))
    got.pop("wall_time_s")
    want.pop("wall_time_s")
    self.assertEqual(got, want)

  def test_shards_cover_the_plan_once(self):
    items = dataset.plan(SPEC)
    for n in (1, 2, 3, 7):
      taken = [it.part_name for i in range(n)
               for it in dataset.Shard(i, n).take(items)]
      self.assertCountEqual(taken, [it.part_name for it in items])
    self.assertEqual(dataset.Shard.parse(" 1/3 "), dataset.Shard(1, 3))
    for bad in ("2/2", "-1/2", "1", "a/b", "0/0", "1/2/3", ""):
      with self.assertRaisesRegex(dataset.scene_lib.InputError,
                                  "allowed: i/N"):
        dataset.Shard.parse(bad)

  def test_assembly_with_missing_parts_is_refused(self):
    with tempfile.TemporaryDirectory() as d:
      with self.assertRaisesRegex(dataset.scene_lib.InputError,
                                  "holds no parts"):
        dataset.assemble_parts(SPEC, d)
      parts = os.path.join(d, "parts")
      os.makedirs(parts)
      mpm_io.write_json(os.path.join(parts, "spec.json"),
                        dataclasses.asdict(SPEC))
      with self.assertRaisesRegex(dataset.scene_lib.InputError,
                                  "5 of 5 parts are missing"):
        dataset.assemble_parts(SPEC, d)
      self.assertEqual(os.listdir(parts), ["spec.json"])

  def test_a_shard_runs_beside_others_but_not_twice(self):
    with tempfile.TemporaryDirectory() as d:
      os.makedirs(os.path.join(d, "parts"))
      lock = os.path.join(d, "parts", ".shard-0-of-2.lock")
      with workers_lib.locked(lock, "busy"):
        with self.assertRaisesRegex(workers_lib.GeneratorBusyError,
                                    "shard 0/2 is already being generated"):
          dataset.generate(SPEC, d, workers=1, shard=dataset.Shard(0, 2))
      with dataset._exclusive(d):  # pylint: disable=protected-access
        with self.assertRaisesRegex(workers_lib.GeneratorBusyError,
                                    "not sharded"):
          dataset.generate(SPEC, d, workers=1, shard=dataset.Shard(1, 2))

  def test_spec_file_first_writer_wins(self):
    with tempfile.TemporaryDirectory() as d:
      parts = os.path.join(d, "parts")
      os.makedirs(parts)
      dataset._write_spec_once(SPEC, parts)  # pylint: disable=protected-access
      dataset._write_spec_once(SPEC, parts)  # pylint: disable=protected-access
      other = dataclasses.replace(SPEC, num_frames=8)
      write_once = dataset._write_spec_once  # pylint: disable=protected-access
      with self.assertRaisesRegex(dataset.scene_lib.InputError,
                                  "num_frames 12 .this config: 8."):
        write_once(other, parts)
      self.assertEqual(os.listdir(parts), ["spec.json"])
      self.assertEqual(mpm_io.read_json(os.path.join(parts, "spec.json")),
                       dataclasses.asdict(SPEC))

  def test_verify_accepts_sound_and_reports_broken(self):
    self.assertEqual(dataset.verify(self.ref, reproduce=1), [])
    with tempfile.TemporaryDirectory() as d:
      for name in os.listdir(self.ref):
        with open(os.path.join(self.ref, name), "rb") as src, open(
            os.path.join(d, name), "wb") as dst:
          dst.write(src.read())
      with h5py.File(os.path.join(d, "train.h5"), "a") as f:
        f["00001/positions"][3, 0, 0] = np.nan
        f["00002/positions"][1, 0, 0] += 0.01
      problems = dataset.verify(d, reproduce=3)
      self.assertTrue(any("00001" in p and "not finite" in p
                          for p in problems), problems)
      self.assertTrue(any("00002" in p and "does not reproduce" in p
                          for p in problems), problems)


class OtherSpecTest(absltest.TestCase):
  """A directory of another spec's dataset or parts is refused, not resumed
  (no simulation: the refusal comes first)."""

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name

  def test_other_parts_are_refused(self):
    os.makedirs(os.path.join(self.dir, "parts"))
    other = dataclasses.replace(SPEC, num_frames=20)
    mpm_io.write_json(os.path.join(self.dir, "parts", "spec.json"),
                      dataclasses.asdict(other))
    with self.assertRaisesRegex(
        dataset.scene_lib.InputError, "holds an unfinished dataset of another "
        "config: its num_frames 20 \\(this config: 12\\)"):
      dataset.generate(SPEC, self.dir, workers=1)
    dataset.check_target(other, self.dir)  # the same spec resumes

  def test_parts_of_another_config_without_spec_file_are_refused(self):
    # Parts from a version that kept no spec.json: each part's stored scene
    # is compared with the scene this config plans for it.
    parts = os.path.join(self.dir, "parts")
    os.makedirs(parts)
    mine = dataset.plan(SPEC)[0]
    theirs = dataset.plan(dataclasses.replace(SPEC, num_frames=20))[0]
    self.assertEqual(theirs.part_name, mine.part_name)

    def write_part(item):
      positions = np.zeros((3, 4, 2), np.float32)  # shape-valid stand-in
      mpm_io.write_trajectories(
          os.path.join(parts, item.part_name),
          [mpm_io.Trajectory(positions, np.zeros((0, 2)), np.zeros(0, int),
                             item.scene, item.seed)])

    write_part(theirs)
    with self.assertRaisesRegex(
        dataset.scene_lib.InputError,
        f"{mine.part_name} .*another config; use another directory"):
      dataset.generate(SPEC, self.dir, workers=1)
    self.assertEqual(sorted(os.listdir(parts)), [mine.part_name])  # no spec

  def test_other_dataset_is_refused(self):
    mpm_io.write_json(os.path.join(self.dir, "metadata.json"),
                      {"spec": dataclasses.asdict(SPEC), "num_train": 3})
    with self.assertRaisesRegex(dataset.scene_lib.InputError,
                                "its num_train 3 \\(this config: 4\\)"):
      dataset.generate(dataclasses.replace(SPEC, num_train=4), self.dir)
    self.assertEqual(dataset.generate(SPEC, self.dir)["num_train"], 3)

  def test_spec_values_are_checked(self):
    with self.assertRaisesRegex(ValueError, "dataset.num_test = 0; allowed"):
      dataclasses.replace(SPEC, num_test=0)
    with self.assertRaisesRegex(ValueError, "dataset.rheology = 'mui'; "
                                "allowed: one of \\['drucker_prager', "
                                "'mu_i', 'mu_i_regularized', "
                                "'mu_i_compressible'\\]"):
      dataclasses.replace(SPEC, rheology="mui")

  def test_a_dataset_made_before_the_rheology_key_is_drucker_prager(self):
    stored = dataclasses.asdict(SPEC)
    del stored["rheology"]
    mpm_io.write_json(os.path.join(self.dir, "metadata.json"),
                      {"spec": stored, "num_train": 3})
    dataset.check_target(SPEC, self.dir)
    with self.assertRaisesRegex(dataset.scene_lib.InputError,
                                "its rheology 'drucker_prager' \\(this "
                                "config: 'mu_i'\\)"):
      dataset.check_target(dataclasses.replace(SPEC, rheology="mu_i"),
                           self.dir)

  def test_a_mu_i_dataset_plans_the_same_scenes_with_mu_i_sand(self):
    dp = dataset.plan(SPEC)
    mu_i = dataset.plan(dataclasses.replace(SPEC, rheology="mu_i"))
    for a, b in zip(dp, mu_i):
      self.assertEqual(b.scene.material.rheology, "mu_i")
      self.assertEqual(dataclasses.replace(b.scene, material=a.scene.material),
                       a.scene)


class OverlapTest(absltest.TestCase):

  def test_overlap_equals_pairwise_comparison(self):
    # The small config's plan, its first 200 training and 21 test scenes:
    # every repeat found by comparing every pair of scene dicts.
    spec = dataset.DatasetSpec(num_train=200, num_test=21, spacing=0.01)
    plans = dataset.plan(spec)
    found = dataset.overlap(plans)

    def same(a, b):
      da, db = a.scene.to_dict(), b.scene.to_dict()
      da.pop("name")
      db.pop("name")
      return da == db
    train = [p for p in plans if p.split == "train"]
    test = [p for p in plans if p.split == "test"]
    in_train = [t.scene.name for t in test
                if any(same(t, p) for p in train)]
    repeats = [t.scene.name for i, t in enumerate(test)
               if t.scene.name not in in_train
               and any(same(t, u) for u in test[:i])]
    self.assertEqual(list(found.test_in_train), in_train)
    self.assertEqual(list(found.test_repeats), repeats)
    distinct = lambda ps: sum(not any(same(p, q) for q in ps[:i])
                              for i, p in enumerate(ps))
    self.assertEqual(found.distinct_train, distinct(train))
    self.assertEqual(found.distinct_test, distinct(test))
    # What it is there to show: scenes without obstacles repeat (their sand
    # box is all that varies), scenes with obstacles do not.
    self.assertNotEmpty(found.test_in_train)
    for name in found.test_in_train + found.test_repeats:
      self.assertEqual(dataset.group_of(name), "none")
      self.assertTrue(found.seen(name))
    self.assertLess(found.distinct_train, len(train))
    self.assertFalse(found.seen(test[1].scene.name))


class ExclusiveGenerationTest(absltest.TestCase):

  def test_a_second_generator_on_the_same_directory_fails(self):
    with tempfile.TemporaryDirectory() as d:
      with dataset._exclusive(d):  # pylint: disable=protected-access
        with self.assertRaisesRegex(workers_lib.GeneratorBusyError,
                                    "another generator"):
          dataset.generate(SPEC, d, workers=1)
      self.assertEqual(os.listdir(d), [])

  def test_only_temp_files_of_dead_writers_are_removed(self):
    with tempfile.TemporaryDirectory() as d:
      dead = subprocess.Popen([sys.executable, "-c", "pass"])
      dead.wait()
      live = os.path.join(d, f"train_00000.h5.tmp-{os.getpid()}")
      stale = os.path.join(d, f"train_00001.h5.tmp-{dead.pid}")
      for path in (live, stale):
        with open(path, "wb") as f:
          f.write(b"\x89HDF half written")
      tagged_dead = f"{mpm_io.temp_path(os.path.join(d, 'train_00002.h5'))}"
      tagged_dead = tagged_dead.rsplit("-", 1)[0] + f"-{dead.pid}"
      tagged_live = mpm_io.temp_path(os.path.join(d, "train_00003.h5"))
      # Another host's pid says nothing about its writer here: kept.
      other_host = os.path.join(d, f"train_00004.h5.tmp-elsewhere-{dead.pid}")
      for path in (tagged_dead, tagged_live, other_host):
        with open(path, "wb") as f:
          f.write(b"\x89HDF half written")
      workers_lib.remove_stale_temps(d)
      self.assertCountEqual(os.listdir(d), [
          os.path.basename(p) for p in (live, tagged_live, other_host)])


class WorkerLifetimeTest(absltest.TestCase):

  def test_watchdog_ends_an_orphan_where_prctl_is_missing(self):
    child = (
        "import sys, time\n"
        "from mpm import workers\n"
        "sys.platform = 'darwin'  # no prctl: the watchdog thread\n"
        "workers.die_with_parent(int(sys.argv[1]), poll_s=0.05)\n"
        "print('ready', flush=True)\n"
        "time.sleep(60)\n")
    parent = (
        "import os, subprocess, sys\n"
        f"child = subprocess.Popen([sys.executable, '-c', {child!r}, "
        "str(os.getpid())])\n"
        "print(child.pid, flush=True)\n"
        "child.wait()\n")
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu")
    proc = subprocess.Popen([sys.executable, "-c", parent], env=env,
                            stdout=subprocess.PIPE, text=True)
    child_pid = int(proc.stdout.readline())
    self.assertEqual(proc.stdout.readline().strip(), "ready")
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stdout.close()
    deadline = time.time() + 5
    while time.time() < deadline and _alive(child_pid):
      time.sleep(0.05)
    alive = _alive(child_pid)
    if alive:
      os.kill(child_pid, signal.SIGKILL)
    self.assertFalse(alive, "the orphan outlived its parent")


class WriteCsvTest(absltest.TestCase):

  def test_round_trip_first_row_keys_no_temporaries(self):
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    d = tmp.name
    path = os.path.join(d, "rows.csv")
    mpm_io.write_csv(path, [{"a": 1, "b": "x,y"}, {"a": 2.5, "b": "", "c": 9}])
    with open(path, newline="") as f:
      self.assertEqual(list(csv.DictReader(f)),
                       [{"a": "1", "b": "x,y"}, {"a": "2.5", "b": ""}])
    self.assertEqual(os.listdir(d), ["rows.csv"])
    mpm_io.write_csv(os.path.join(d, "none.csv"), [])
    self.assertEqual(os.listdir(d), ["rows.csv"])


class FileErrorTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name

  def _write(self, name, mutate):
    path = os.path.join(self.dir, name)
    with h5py.File(path, "w") as f:
      mutate(f)
    return path

  def test_missing_file(self):
    with self.assertRaisesRegex(mpm_io.FormatError, "no such trajectory file"):
      mpm_io.read_header(os.path.join(self.dir, "nope.h5"))

  def test_corrupt_file(self):
    path = os.path.join(self.dir, "bad.h5")
    with open(path, "wb") as f:
      f.write(b"not an hdf5 file at all")
    with self.assertRaisesRegex(mpm_io.FormatError, "not a readable HDF5"):
      list(mpm_io.read_trajectories(path))

  def test_wrong_format_version(self):
    path = self._write("v.h5", lambda f: f.attrs.update(format_version=99))
    with self.assertRaisesRegex(mpm_io.FormatError, "format_version 99"):
      list(mpm_io.read_trajectories(path))

  def test_wrong_shapes(self):
    def mutate(f):
      f.attrs["format_version"] = mpm_io.FORMAT_VERSION
      g = f.create_group("00000")
      g["positions"] = np.zeros((5, 3), np.float32)
      g["particle_type"] = np.zeros(3, np.int32)
      g["boundary_positions"] = np.zeros((2, 2), np.float32)
      g["boundary_type"] = np.zeros(2, np.int32)
      g.attrs["scene"] = '{"num_frames": 5}'
      g.attrs["seed"] = 0
      g.attrs["wall_time_s"] = 0.0
    path = self._write("s.h5", mutate)
    with self.assertRaisesRegex(mpm_io.FormatError, r"expected \[T, N, 2\]"):
      list(mpm_io.read_trajectories(path))

  def test_missing_entry(self):
    def mutate(f):
      f.attrs["format_version"] = mpm_io.FORMAT_VERSION
      f.create_group("00000")
    path = self._write("m.h5", mutate)
    with self.assertRaisesRegex(mpm_io.FormatError, "missing or unreadable"):
      list(mpm_io.read_trajectories(path))

  def test_incomplete_dataset(self):
    self.assertEqual(len(dataset.verify(self.dir)), 1)
    self.assertIn("incomplete", dataset.verify(self.dir)[0])

  def test_non_finite_positions_are_not_written(self):
    t = mpm_io.Trajectory(np.full((3, 2, 2), np.nan, np.float32),
                          np.zeros((1, 2), np.float32), np.zeros(1, np.int32),
                          dataset.plan(SPEC)[0].scene)
    path = os.path.join(self.dir, "nan.h5")
    with self.assertRaisesRegex(ValueError, "not finite"):
      mpm_io.write_trajectories(path, [t], stats={
          k: np.zeros(2) for k in ("vel_mean", "vel_std", "acc_mean",
                                   "acc_std")})
    self.assertFalse(os.path.exists(path))
    self.assertEqual(os.listdir(self.dir), [])


if __name__ == "__main__":
  absltest.main()
