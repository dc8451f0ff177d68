"""Pushforward loss of a trained model: the target moved by the start's noise
(simulator.shift_target, since commit c761201), the unmoved true frame
(before it), and the one-step loss, on the same training windows (P = 3).

  python docs/results/pushforward_target_loss.py experiments/runs/rest_cleanrest_avg5 60
"""
import sys, numpy as np, jax, jax.numpy as jnp
from gnsjax import run as run_lib, train, data
from experiments.configs import small
run = run_lib.load_run(sys.argv[1])
config = small.get_config(); config.update(run.config)
config.train.pushforward_steps = 3; config.train.pushforward_probability = 1.0
trainer = train.Trainer(config, run.problem)
params = trainer.replicate(run.params)
c = run.problem.input_frames; P = 3
res = {"new": [], "old": [], "onestep": []}
with data.WindowDataset(data.split_path("data/small1000", "train"), input_frames=c + P, seed=0,
                        frame_stride=config.train.frame_stride, motion_weighting=config.train.motion_weighting) as ds:
  for i in range(int(sys.argv[2])):
    batch = trainer.make_batch([ds[2 * i], ds[2 * i + 1]])
    key = jax.random.key(i)
    g, t = trainer.batch_arrays(batch, key, params=params, pushforward=P)
    res["new"].append(float(trainer.eval_loss(params, g, t)))
    old_t = trainer.put(batch.positions[:, c + P])
    res["old"].append(float(trainer.eval_loss(params, g, old_t)))
    g1, t1 = trainer.batch_arrays(batch, key)
    res["onestep"].append(float(trainer.eval_loss(params, g1, t1)))
for k, v in res.items():
  print(k, "mean %.4g median %.4g max %.4g" % (np.mean(v), np.median(v), np.max(v)))
