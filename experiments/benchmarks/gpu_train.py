"""The GPU command's train part: training's steps per second on this device.

Steps per second of ``train.train_and_evaluate`` with the paper config
(batch 2, host batches, graphs built per step) on a dataset of paper
trajectories generated first, evaluation off; the median of ``log_every``
intervals after a warm-up, projected to 1.5 M and 2 M steps beside the
paper's 81.5 h and 134 h on a V100. Then the same for a second config
(the small one), projected to its own ``num_steps``, under "second".
"""

import csv
import os
import statistics
from typing import Any, Callable

from experiments import timing
from experiments.benchmarks import gns_programs
from experiments.benchmarks.gpu_report import PAPER_TRAINING_H
from experiments.benchmarks.gpu_sizes import Sizes
from gnsjax import train
from mpm import dataset as mpm_dataset


def measure_training(sizes: Sizes, log: Callable[[str], None],
                     workdir: str) -> dict[str, Any]:
  """The train part: ``sizes.train_config``'s figures, and those of
  ``sizes.second_train_config`` (if any) under "second"."""
  out = measure_config(sizes, sizes.train_config, log,
                       os.path.join(workdir, "first"))
  if sizes.second_train_config:
    out["second"] = measure_config(sizes, sizes.second_train_config, log,
                                   os.path.join(workdir, "second"))
  return out


def measure_config(sizes: Sizes, name: str, log: Callable[[str], None],
                   workdir: str) -> dict[str, Any]:
  """A dataset of config ``name``'s kind, then ``train.train_and_evaluate``
  for warm-up + timed steps (evaluation off, one checkpoint at the end),
  its logged steps per second."""
  config = gns_programs.load_config(name)
  own_steps = config.train.num_steps
  d = config.dataset
  spec = mpm_dataset.DatasetSpec(num_train=sizes.train_trajectories,
                                 num_test=1, num_frames=sizes.train_frames,
                                 seed=d.seed, spacing=d.spacing,
                                 connectivity_radius=d.connectivity_radius)
  data_dir = os.path.join(workdir, "data")
  _, gen_s = timing.wall(lambda: mpm_dataset.generate(spec, data_dir,
                                                      workers=1))
  total = sizes.train_warmup + sizes.train_steps
  config.train.num_steps = total
  config.log_every = sizes.train_log_every
  config.eval.every_steps = 0
  config.checkpoint.every_steps = 10 * total
  config.checkpoint.named_steps = ()
  config.checkpoint.keep = 1
  run_dir = os.path.join(workdir, "run")
  _, wall_s = timing.wall(lambda: train.train_and_evaluate(config, data_dir,
                                                           run_dir))
  with open(os.path.join(run_dir, "metrics.csv")) as f:
    rows = [{"step": int(r["step"]), "steps_per_s": float(r["steps_per_s"]),
             "wall_time_s": float(r["wall_time_s"])}
            for r in csv.DictReader(f)]
  timed = [r for r in rows if r["step"] > sizes.train_warmup]
  rate = statistics.median(r["steps_per_s"] for r in timed)
  at_warmup = [r for r in rows if r["step"] <= sizes.train_warmup]
  t0 = at_warmup[-1]["wall_time_s"] if at_warmup else 0.0
  overall = (timed[-1]["step"] - (at_warmup[-1]["step"] if at_warmup else 0)
             ) / (timed[-1]["wall_time_s"] - t0)
  out = {"config": name, "batch_size": config.train.batch_size,
         "latent_size": config.model.latent_size,
         "num_message_passing_steps":
             config.model.num_message_passing_steps,
         "dataset": {"trajectories": sizes.train_trajectories,
                     "frames": sizes.train_frames, "generate_s": gen_s},
         "warmup_steps": sizes.train_warmup, "timed_steps": sizes.train_steps,
         "log_every": sizes.train_log_every, "intervals": timed,
         "steps_per_s": rate, "steps_per_s_overall": overall,
         "run_wall_s": wall_s,
         "projected_h": {str(s): s / rate / 3600 for s in PAPER_TRAINING_H},
         "own_num_steps": own_steps,
         "own_projected_h": own_steps / rate / 3600}
  log(f"training ({name} config, batch "
      f"{config.train.batch_size}): {rate:.3g} steps/s (median of "
      f"{len(timed)} intervals of {sizes.train_log_every}; overall "
      f"{overall:.3g}) -> 1.5 M steps in "
      f"{out['projected_h']['1500000']:.3g} h, its own {own_steps} in "
      f"{out['own_projected_h']:.3g} h")
  return out
