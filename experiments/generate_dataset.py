"""Generates (or resumes, or verifies) a dataset of MPM trajectories.

  python -m experiments.generate_dataset --config=experiments/configs/paper.py \
      --out=DIR [--workers=2] [--verify]

Killed at any moment, the same command continues where it stopped. A
directory holding a dataset (or the parts of one) of another config is
refused.
"""

import sys

from absl import flags
from ml_collections import config_flags
import tqdm

from mpm import dataset
from experiments import runtime

_CONFIG = config_flags.DEFINE_config_file("config", None, "Config file.",
                                          lock_config=True)
_OUT = flags.DEFINE_string("out", None, "Dataset directory.")
_WORKERS = flags.DEFINE_integer("workers", None,
                                "Processes (default: the config's).",
                                lower_bound=1)
_VERIFY = flags.DEFINE_bool("verify", False,
                            "Check an existing dataset instead of generating.")


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
  spec = dataset.DatasetSpec(**_CONFIG.value.dataset.to_dict())
  runtime.writable("out", _OUT.value)
  dataset.check_target(spec, _OUT.value)
  workers = _WORKERS.value or _CONFIG.value.workers
  total = spec.num_train + spec.num_test
  cache = runtime.enable_compilation_cache()
  with tqdm.tqdm(total=total, unit="traj") as bar:
    def progress(done, _, wall):
      bar.update(done - bar.n)
      if wall:
        bar.set_postfix(last_s=f"{wall:.2f}")
    metadata = dataset.generate(spec, _OUT.value, workers=workers,
                                progress=progress, compilation_cache=cache)
  wall = metadata["wall_time_s"]
  print(f"{_OUT.value}: {metadata['num_train']} train + "
        f"{metadata['num_test']} test "
        f"trajectories; simulation time {wall['train']:.1f} s + "
        f"{wall['test']:.1f} s")


if __name__ == "__main__":
  flags.mark_flags_as_required(["config", "out"])
  runtime.run(main)
