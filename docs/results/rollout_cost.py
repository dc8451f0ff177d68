"""Two models' rollout cost, in one process on the same trajectories.

Each model rolls out test trajectories 0-2 of data/small1000 (175, 250 and
375 particles) with the solid constraint: one warm-up, then the median of
three timed rollouts, synchronised.

  python docs/results/rollout_cost.py MODEL_A MODEL_B
"""
import sys
import time

import jax
import numpy as np

from gnsjax import data
from gnsjax import rollout
from gnsjax import run as run_lib

REPEATS = 3


def main(model_dirs):
  path = data.split_path("data/small1000", "test")
  trajectories = [t for i, t in enumerate(data.trajectories(path)) if i < 3]
  print("| model | scene | particles | s / trajectory (median of 3) |")
  print("|---|---|---:|---:|")
  for model_dir in model_dirs:
    run = run_lib.load_run(model_dir)
    for t in trajectories:
      rollout.rollout_trajectory(run.model, run.params, t, run.problem)
      seconds = []
      for _ in range(REPEATS):
        start = time.perf_counter()
        out = rollout.rollout_trajectory(run.model, run.params, t,
                                         run.problem)
        jax.block_until_ready(out.positions)
        seconds.append(time.perf_counter() - start)
      print(f"| {model_dir} | {t.scene.name} | {t.positions.shape[1]} | "
            f"{np.median(seconds):.2f} |")


if __name__ == "__main__":
  main(sys.argv[1:])
