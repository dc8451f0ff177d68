"""How fast training batches are fed: host windows against device windows.

  python -m experiments.benchmarks --what=input --read_data=data/small \\
      --out=docs/benchmarks

On a dataset of the small config (models without boundary particles), in one
run, interleaved:

* ``host``: ``batching.make_batch`` of windows read from HDF5 and padded in
  numpy, then copied to the device (the path of models with boundary
  particles);
* ``device``: ``batching.DeviceWindows.batch``, a jitted gather from the
  split stored on the device, from (trajectory, frame) indices the host
  computes (``data.WindowDataset.locate``);
* ``device_graph``: the device gather plus what every training step adds on
  the device before the model runs: noise and the radius graph (jax-md
  neighbour list update), i.e. ``Trainer.batch_arrays``.

Figures are batches per second (batch size of the config), medians of
repeats of ``steps`` batches each, synchronised.
"""

import time

import jax
import numpy as np

from experiments import timing
from experiments.configs import small
from gnsjax import batching
from gnsjax import data
from gnsjax import run as run_lib
from gnsjax import train


def run_benchmark(data_dir: str, out_dir: str, *, quick: bool = False,
                  steps: int = 100, config=None) -> dict:
  """Measures the three feeds on ``data_dir``'s training split; writes
  ``input_benchmark.{json,md}`` in ``out_dir``.

  Args:
    config: the training config whose batches are fed (default
      ``configs/small.py``); boundary particles are switched off.
  """
  config = small.get_config() if config is None else config
  config.model.boundary_particles = False
  problem = run_lib.load_problem(data_dir, config)
  trainer = train.Trainer(config, problem)
  tcfg = config.train
  path = data.split_path(data_dir, "train")
  dataset = data.WindowDataset(path, input_frames=tcfg.input_frames,
                               frame_stride=tcfg.frame_stride, seed=0)
  env = timing.environment(quick)
  start = time.perf_counter()
  windows = batching.DeviceWindows(
      path, problem.spec, input_frames=tcfg.input_frames,
      frame_stride=tcfg.frame_stride, node_bucket=tcfg.node_bucket,
      sdf_spacing=problem.sdf_spacing)
  jax.block_until_ready(windows.positions)
  load_s = time.perf_counter() - start
  steps = 10 if quick else steps
  b = tcfg.batch_size
  key = jax.random.key(0)

  def where(step):
    return np.array([dataset.locate(step * b + i) for i in range(b)])

  def host():
    out = None
    for s in range(steps):
      batch = trainer.make_batch([dataset[s * b + i] for i in range(b)])
      out = jax.device_put(batch.positions), jax.device_put(batch.solids)
    return out

  def device():
    out = None
    for s in range(steps):
      w = where(s)
      out = windows.batch(w[:, 0], w[:, 1])
    return out

  def device_graph():
    out = None
    for s in range(steps):
      w = where(s)
      out = trainer.batch_arrays(windows.batch(w[:, 0], w[:, 1]),
                                 jax.random.fold_in(key, s))
    return out

  results = timing.time_calls({"host": host, "device": device,
                               "device_graph": device_graph},
                              repeats=3 if quick else 5)
  rates = {name: steps / r["median_s"] for name, r in results.items()}
  record = {"environment": env, "data": data_dir, "batch_size": b,
            "steps_per_repeat": steps, "device_load_s": load_s,
            "timings": results, "batches_per_s": rates}
  timing.end_environment(env)
  lines = [
      "# Training input rate", "",
      f"Batches of {b} windows per second, medians of repeats of {steps} "
      f"batches (`{data_dir}`, one run, interleaved). Loading the split onto "
      f"the device took {load_s:.1f} s.", "",
      "| feed | batches/s |", "|---|---|"]
  lines += [f"| {name} | {rate:.0f} |" for name, rate in rates.items()]
  timing.write_results(out_dir, "input_benchmark", quick, record,
                       "\n".join(lines) + "\n")
  return record
