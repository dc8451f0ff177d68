"""Two models' rollout cost, in one process on the same trajectories.

Each model rolls out test trajectories 0-2 of data/small1000 (175, 250 and
375 particles) with the solid constraint, timed by the project's rules
(``experiments.timing.time_calls``: one warm-up, then the two models'
calls interleaved, the median of three, synchronised).

  python docs/results/rollout_cost.py MODEL_A MODEL_B
"""
import sys

from experiments import timing
from gnsjax import data
from gnsjax import rollout
from gnsjax import run as run_lib

REPEATS = 3


def main(model_dirs):
  path = data.split_path("data/small1000", "test")
  trajectories = [t for i, t in enumerate(data.trajectories(path)) if i < 3]
  runs = {model_dir: run_lib.load_run(model_dir) for model_dir in model_dirs}
  print("| model | scene | particles | s / trajectory (median of 3) |")
  print("|---|---|---:|---:|")
  for t in trajectories:
    calls = {
        model_dir: (lambda run=run: rollout.rollout_trajectory(
            run.model, run.params, t, run.problem).positions)
        for model_dir, run in runs.items()}
    for model_dir, figure in timing.time_calls(calls, REPEATS).items():
      print(f"| {model_dir} | {t.scene.name} | {t.positions.shape[1]} | "
            f"{figure['median_s']:.2f} |")


if __name__ == "__main__":
  main(sys.argv[1:])
