"""Generates (or resumes, or verifies) a dataset of MPM trajectories.

  python -m experiments.generate_dataset --config=experiments/configs/paper.py \
      --out=DIR [--workers=2 | --batch=64] [--verify]

Killed at any moment, the same command continues where it stopped. A
directory holding a dataset (or the parts of one) of another config is
refused.

Across processes or hosts sharing a filesystem (docs/scaling.md): run
``--shard=i/N`` for each i in 0..N-1 (in any order, at once or not), then
once ``--assemble``; the dataset is the one a single run writes.
"""

import shutil
import sys

from absl import flags
from ml_collections import config_flags
import tqdm

from mpm import budget
from mpm import dataset
from mpm import sampler
from experiments import runtime

_CONFIG = config_flags.DEFINE_config_file(
    "config", None, "Config file (not needed with --verify).",
    lock_config=True)
_OUT = flags.DEFINE_string("out", None, "Dataset directory.")
_WORKERS = flags.DEFINE_integer("workers", None,
                                "Processes (default: the config's).",
                                lower_bound=1)
_BATCH = flags.DEFINE_integer(
    "batch", 1, "Scenes per vmapped call, in one process (for an "
    "accelerator; needs --workers=1); within 1e-6 m of one at a time.",
    lower_bound=1)
_VERIFY = flags.DEFINE_bool("verify", False,
                            "Check an existing dataset instead of generating.")
_SHARD = flags.DEFINE_string(
    "shard", None, "i/N: simulate only share i of N of the trajectories "
    "(then run --assemble once all N are done).")
_ASSEMBLE = flags.DEFINE_bool(
    "assemble", False, "Assemble the parts the --shard runs wrote into the "
    "dataset.")


def main(argv):
  del argv
  if _VERIFY.value:
    runtime.existing_dir("out", _OUT.value)
    problems = dataset.verify(_OUT.value)
    for p in problems:
      print(f"PROBLEM: {p}")
    print(f"{_OUT.value}: {'OK' if not problems else 'BROKEN'} "
          f"({len(problems)} problems)")
    sys.exit(1 if problems else 0)
  if _CONFIG.value is None:
    raise runtime.InputError("--config is required to generate (e.g. "
                             "--config=experiments/configs/small.py); only "
                             "--verify works without it")
  spec = dataset.DatasetSpec(**_CONFIG.value.dataset.to_dict())
  if _ASSEMBLE.value and _SHARD.value is not None:
    raise runtime.InputError(f"--shard={_SHARD.value} with --assemble; "
                             "allowed: one of them")
  shard = None if _SHARD.value is None else dataset.Shard.parse(_SHARD.value)
  workers = _WORKERS.value or _CONFIG.value.workers
  if _BATCH.value > 1:
    if _WORKERS.value not in (None, 1):
      raise runtime.InputError(f"--batch={_BATCH.value} with --workers="
                               f"{_WORKERS.value}; allowed: --batch > 1 only "
                               "with --workers=1 (one process drives the "
                               "batches)")
    workers = 1
  if not _ASSEMBLE.value:
    _check_budget(spec, max(workers, _BATCH.value), shard,
                  "--batch" if _BATCH.value > 1 else "--workers")
  runtime.writable("out", _OUT.value)
  dataset.check_target(spec, _OUT.value)
  if _ASSEMBLE.value:
    runtime.existing_dir("out", _OUT.value)
    metadata = dataset.assemble_parts(spec, _OUT.value)
    _report(metadata)
    return
  total = (spec.num_train + spec.num_test if shard is None else
           len(shard.take(dataset.plan(spec))))
  cache = runtime.enable_compilation_cache()
  with tqdm.tqdm(total=total, unit="traj") as bar:
    def progress(done, _, wall):
      bar.update(done - bar.n)
      if wall:
        bar.set_postfix(last_s=f"{wall:.2f}")
    metadata = dataset.generate(spec, _OUT.value, workers=workers,
                                progress=progress, compilation_cache=cache,
                                shard=shard, batch=_BATCH.value)
  if "shard" in metadata:
    print(f"{_OUT.value}: shard {metadata['shard']} done "
          f"({metadata['parts']} trajectories); once every shard is done, "
          "run once with --assemble")
    return
  _report(metadata)


def _check_budget(spec, workers, shard, scenes_flag):
  """Refuses a dataset whose largest scene cannot fit this machine's memory
  once per worker (or per scene of a batch: ``scenes_flag`` names which),
  or whose files cannot fit the disk; warns, with the estimate, if it
  takes hours."""
  largest = max(sampler.PARTICLE_RANGE + dataset.TEST_PARTICLES)
  scene = sampler.sample_scene(0, num_particles=spec.particles(largest),
                               num_frames=spec.num_frames,
                               spacing=spec.spacing)
  count = spec.num_train + spec.num_test
  if shard is not None:
    count = -(-count // shard.count)
  workers = min(workers, count)
  cost = budget.check_fits(scene, scenes=workers, names={
      "spacing": "dataset.spacing", "dx": None,
      "num_frames": "dataset.num_frames", "scenes": scenes_flag})
  disk = count * spec.num_frames * cost.particles * 8  # float32 x, y
  parent = runtime.existing_ancestor(_OUT.value)
  free = shutil.disk_usage(parent).free
  if disk > free:
    raise runtime.InputError(
        f"dataset: {count:,} trajectories of {spec.num_frames:,} frames and "
        f"up to {cost.particles:,} particles take up to "
        f"{budget.gib(disk)}; {parent} has {budget.gib(free)} free")
  warning = budget.warning(cost, count, workers)
  if warning:
    print(warning, file=sys.stderr)


def _report(metadata):
  wall = metadata["wall_time_s"]
  print(f"{_OUT.value}: {metadata['num_train']} train + "
        f"{metadata['num_test']} test "
        f"trajectories; simulation time {wall['train']:.1f} s + "
        f"{wall['test']:.1f} s")


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
