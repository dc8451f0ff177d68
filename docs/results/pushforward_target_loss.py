"""Pushforward loss of a trained model: the target moved by the start's noise
(simulator.shift_target, since commit c761201), the unmoved true frame
(before it), and the one-step loss, on the same training windows (P = 3).

  python docs/results/pushforward_target_loss.py experiments/runs/rest_cleanrest_avg5 60
"""
import sys

import jax
import numpy as np

from experiments.configs import small
from gnsjax import data
from gnsjax import run as run_lib
from gnsjax import train

P = 3
run = run_lib.load_run(sys.argv[1])
# A run stored before a config option existed lacks its key: the defaults.
config = small.get_config()
config.update(run.config)
config.train.pushforward_steps = P
config.train.pushforward_probability = 1.0
trainer = train.Trainer(config, run.problem)
params = trainer.replicate(run.params)
c = run.problem.input_frames
losses = {"moved": [], "unmoved": [], "one-step": []}
with data.WindowDataset(data.split_path("data/small1000", "train"),
                        input_frames=c + P, seed=0,
                        frame_stride=config.train.frame_stride,
                        motion_weighting=config.train.motion_weighting) as ds:
  for i in range(int(sys.argv[2])):
    batch = trainer.make_batch([ds[2 * i], ds[2 * i + 1]])
    key = jax.random.key(i)
    graphs, target = trainer.batch_arrays(batch, key, params=params,
                                          pushforward=P)
    losses["moved"].append(float(trainer.eval_loss(params, graphs, target)))
    unmoved = trainer.put(batch.positions[:, c + P])
    losses["unmoved"].append(float(trainer.eval_loss(params, graphs,
                                                     unmoved)))
    graphs, target = trainer.batch_arrays(batch, key)
    losses["one-step"].append(float(trainer.eval_loss(params, graphs,
                                                      target)))
for name, v in losses.items():
  print(f"{name}: mean {np.mean(v):.4g} median {np.median(v):.4g} "
        f"max {np.max(v):.4g}")
