"""Training the learned simulator:
``train_and_evaluate(config, data, workdir)``.

Each step: B windows (a pure function of
the step, see ``gnsjax.data.WindowDataset``), padded to a node bucket; random-
walk noise from ``fold_in(key, step)``; a radius graph from the jax-md
neighbour list (reallocated on the host when it overflows, never truncated);
MSE of normalised acceleration (or through K learned steps,
``gnsjax.unrolled``); Adam with gradient clipping and the GNS
exponential learning-rate decay. A run killed at any moment resumes from its
last checkpoint and produces the same losses as an uninterrupted run.

Data-parallel over all devices: the batch axis is sharded over a one-axis
mesh ("batch") and parameters are replicated (``jax.sharding``). Across
processes (``gnsjax.distributed``) the mesh holds every process's devices;
each process reads and pads only its rows of every batch and builds their
graphs, agreeing with the others on the padded node count and the neighbour
lists' sizes, so the losses are those of one process with the same global
batch. Process 0 writes the logs; all save the checkpoints (orbax writes
each once) and all restore them.
"""

import contextlib
import csv
import functools
import math
import os
import time
from typing import Any

from absl import logging
import flax
import jax
import jax.numpy as jnp
import ml_collections
import numpy as np
import optax
import tensorboardX
import tqdm

from gnsjax import batch_kinds
from gnsjax import batching
from gnsjax import checkpoint
from gnsjax import config as config_lib
from gnsjax import data
from gnsjax import distributed
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import noise as noise_lib
from gnsjax import optimizer as optimizer_lib
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import train_eval
from gnsjax import unrolled
from mpm import geometry as mpm_geometry
from mpm import io as mpm_io

InputError = config_lib.InputError


class DivergedError(InputError):
  """The loss turned NaN or infinite: the config's step sizes diverge."""


@flax.struct.dataclass
class TrainState:
  """step [], params, opt_state, key (the run's base PRNG key)."""
  step: jax.Array
  params: Any
  opt_state: Any
  key: jax.Array


def _mesh():
  # Every process's devices: jax.devices() is the same list in all of them.
  devices = np.array(jax.devices())
  return jax.sharding.Mesh(devices, ("batch",))


class Trainer:
  """Compiled pieces of a run; see :func:`train_and_evaluate`."""

  def __init__(self, config, problem: run_lib.Problem):
    self.config = config
    self.problem = problem
    self.model = run_lib.create_model(config.model)
    self.tx = optimizer_lib.create_optimizer(config.train)
    self.mesh = _mesh()
    self.batch_sharding = jax.sharding.NamedSharding(
        self.mesh, jax.sharding.PartitionSpec("batch"))
    self.replicated = jax.sharding.NamedSharding(
        self.mesh, jax.sharding.PartitionSpec())
    self.multi = jax.process_count() > 1
    # In one process None: the code path (and the numbers) of a run that
    # never heard of processes.
    self._agree = distributed.agree_max if self.multi else None
    self._nbrs = {}  # padded node count -> batched neighbour list
    ctx, radius = problem.context, problem.radius
    noise_std = problem.noise_std

    outside = config.train.target_outside_solids
    clean = config.train.clean_fraction
    clean_windows = functools.partial(
        noise_lib.clean_windows, fraction=clean,
        resting_only=config.train.clean_resting_only,
        stride=config.train.frame_stride)

    def prepare(key, positions, moving, solids):
      keys = jax.random.split(key, positions.shape[0])
      std = jnp.full((positions.shape[0],), noise_std, jnp.float32)
      if clean:
        scale = noise_lib.quiet_scale(jax.random.fold_in(key, 2), std.shape,
                                      config.train.clean_scale_min)
        std = jnp.where(clean_windows(key, positions, moving), scale * std,
                        std)
      add = lambda k, x, m, n, s: simulator.add_noise(k, x, m, n, solids=s)
      return jax.vmap(add)(keys, positions, moving, std,
                           solids if outside else None)

    def batch_loss(params, graphs: simulator.Graph, target, weights=None):
      per_window = jax.vmap(
          lambda g, t: simulator.loss(self.model, params, g, t, ctx, radius))(
              graphs, target)
      if weights is not None:
        per_window = per_window * weights
      return jnp.mean(per_window)

    def train_step(state, graphs, target, weights=None):
      loss, grads = jax.value_and_grad(batch_loss)(state.params, graphs,
                                                   target, weights)
      updates, opt_state = self.tx.update(grads, state.opt_state, state.params)
      params = optax.apply_updates(state.params, updates)
      return (state.replace(step=state.step + 1, params=params,
                            opt_state=opt_state),
              {"loss": loss, "grad_norm": optax.tree.norm(grads)})

    self.prepare = jax.jit(prepare)
    self._shift_target = jax.jit(jax.vmap(
        lambda t, o, m, s: simulator.shift_target(t, o, m,
                                                  s if outside else None)))
    self._clean_windows = jax.jit(clean_windows)
    self.eval_loss = jax.jit(batch_loss)
    self.train_step = jax.jit(train_step, donate_argnums=0)
    self._unroll = jax.jit(
        functools.partial(rollout_lib.unroll,
                          simulator.ModelPredictor(self.model)),
        static_argnames=("spec", "length", "project", "batched"))
    self._unrolled_step = unrolled.make_train_step(
        simulator.ModelPredictor(self.model), self.tx, ctx, problem.spec,
        config.train.pushforward_constrained)
    self._pushforward_nbrs = {}
    self._restored_capacities = {}

  def graph_capacities(self) -> dict:
    """The neighbour lists' static sizes, {"train"|"pushforward": {N:
    [edge capacity, cell capacity]}}. They grow with the data a run has
    seen, and they fix the shapes the train step is compiled for, so a
    checkpoint keeps them and a resumed run starts from them
    (``restore_graph_capacities``): its steps then compute exactly what the
    uninterrupted run's did."""
    return {name: {str(n): list(graph.capacities(nbrs))
                   for n, nbrs in lists.items()}
            for name, lists in (("train", self._nbrs),
                                ("pushforward", self._pushforward_nbrs))}

  def restore_graph_capacities(self, capacities: dict) -> None:
    """Lists allocated from now on start at these sizes (at least)."""
    self._restored_capacities = capacities

  def _allocate(self, kind: str, positions: jax.Array):
    saved = self._restored_capacities.get(kind, {}).get(
        str(positions.shape[1]))
    return graph.allocate_batch(self.problem.spec, positions,
                                None if saved is None else tuple(saved),
                                agree=self._agree)

  def init_state(self, seed: int) -> TrainState:
    init_key, key = jax.random.split(jax.random.key(seed))
    params = models.init_params(
        self.model, init_key,
        features.num_node_features(self.config.train.input_frames))
    state = TrainState(jnp.zeros((), jnp.int32), params,
                       self.tx.init(params), key)
    return self.replicate(state)

  def replicate(self, tree):
    """``tree``'s arrays replicated over the mesh (across processes: each
    process gives its copy, the same in all of them)."""
    if not self.multi:
      return jax.device_put(tree, self.replicated)
    # pylint: disable-next=g-import-not-at-top
    from jax.experimental import multihost_utils

    def one(x):
      if isinstance(x, jax.Array) and not x.is_fully_addressable:
        return x  # already global (restored by orbax onto the mesh)
      return multihost_utils.host_local_array_to_global_array(
          x, self.mesh, jax.sharding.PartitionSpec())
    return jax.tree.map(one, tree)

  def graph_edges(self, positions: jax.Array):
    """Senders, receivers [B, E] of the last input frame [B, N, 2] (across
    processes: of this process's rows, from and to host arrays)."""
    if self.multi:
      positions = distributed.process_rows(positions)
    n = positions.shape[1]
    spec = self.problem.spec
    nbrs = self._nbrs.get(n)
    if nbrs is None:
      nbrs = self._allocate("train", positions)
    nbrs, _ = graph.update_or_reallocate(spec, positions, nbrs, batched=True,
                                         agree=self._agree)
    self._nbrs[n] = nbrs
    senders, receivers = _batched_edges(nbrs, n)
    if self.multi:
      senders, receivers = np.asarray(senders), np.asarray(receivers)
    return senders, receivers

  def rows(self, batch_size: int) -> range:
    """The rows of a global batch of ``batch_size`` that this process reads
    (all of them in one process)."""
    index = self.batch_sharding.addressable_devices_indices_map(
        (batch_size,)).values()
    starts = [i[0].indices(batch_size) for i in index]
    return range(min(a for a, _, _ in starts), max(b for _, b, _ in starts))

  def make_batch(self, windows) -> batching.Batch:
    """The padded batch of some windows, with this run's node choice
    (across processes: this process's rows of a batch)."""
    return batching.make_batch(windows, self.problem.spec,
                               self.config.train.node_bucket,
                               self.problem.boundary_particles,
                               self.problem.sdf_spacing, agree=self._agree)

  def put(self, rows: np.ndarray) -> jax.Array:
    """A global array, batch-sharded, from this process's ``rows``."""
    if not self.multi:
      return jax.device_put(rows, self.batch_sharding)
    rows = np.asarray(rows)
    shape = (rows.shape[0] * jax.process_count(),) + rows.shape[1:]
    return jax.make_array_from_process_local_data(self.batch_sharding, rows,
                                                  shape)

  def local_params(self, params):
    """``params`` as arrays this process can use alone (rollouts)."""
    if not self.multi:
      return params
    return jax.tree.map(lambda x: np.asarray(x.addressable_data(0)), params)

  def batch_arrays(self, batch: batching.Batch, key: jax.Array,
                   noise: bool = True, params=None, pushforward: int = 0,
                   rest_pushforward: int = 0
                   ) -> tuple[simulator.Graph, jax.Array]:
    """(graphs with a leading batch axis, targets [B, N, 2]) on the devices.

    The batch holds C + 1 frames per window and more (``pushforward_steps``
    P and ``unroll_steps`` K of the config: C + max(P, K - 1) + 1). Without
    ``pushforward`` the last C + 1 frames are the inputs and the target.
    With ``pushforward`` = P, the last C + P + 1 frames are used: the model
    (``params``) first rolls the first C frames (noisy if ``noise``) P
    steps on, without gradient, with the solid constraint as in a rollout
    unless ``train.pushforward_constrained`` is off; its own predictions
    are then the inputs, and the true frame P steps later, moved by the
    start's noise, the target, so the model learns to correct the errors it
    makes in its own rollouts (Brandstetter et al. 2022, LagrangeBench).
    With ``rest_pushforward`` = R, still windows (``noise.still`` below
    ``train.rest_pushforward_speed``) start from the model's frames R steps
    on and keep their one-step target: the true frame R steps on of resting
    sand is the last (docs/gns.md); with ``train.rest_pushforward_stay``
    the target moves with the model's drift, as with noise: stop there.
    """
    put = self.put
    c = self.problem.input_frames
    positions, moving = put(batch.positions), put(batch.moving)
    types = put(batch.particle_type)
    solids = mpm_geometry.SDFGrid(put(batch.solids), self.problem.sdf_spacing)
    start = positions.shape[1] - c - 1 - pushforward
    window = positions[:, start:start + c + 1]
    if noise:
      inputs, target = self.prepare(key, window, moving, solids)
    else:
      inputs, target = window[:, :-1], window[:, -1]
    if pushforward:
      offset = inputs[:, -1] - window[:, -2]
      inputs = self._push_forward(params, inputs, types, moving, solids,
                                  pushforward)
      target = self._shift_target(positions[:, -1], offset,
                                  moving, solids)
    elif rest_pushforward:
      tcfg = self.config.train
      still = noise_lib.still(positions, moving, tcfg.frame_stride,
                              tcfg.rest_pushforward_speed)
      pushed = self._push_forward(params, inputs, types, moving, solids,
                                  rest_pushforward)
      if tcfg.rest_pushforward_stay:
        target = jnp.where(still[:, None, None], self._shift_target(
            target, pushed[:, -1] - inputs[:, -1], moving, solids), target)
      inputs = jnp.where(still[:, None, None, None], pushed, inputs)
    senders, receivers = self.graph_edges(inputs[:, -1])
    graphs = simulator.Graph(inputs, types, moving, put(senders),
                             put(receivers), solids)
    return graphs, target

  def window_weights(self, batch: batching.Batch, key: jax.Array):
    """float [B]: each window's weight in the training loss, or None when
    all weigh 1: ``train.clean_weight`` for the windows that
    :meth:`batch_arrays` (same ``batch`` and ``key``) left clean, so that
    exact rest, a small target among large ones, is fitted closely."""
    tcfg = self.config.train
    if not tcfg.clean_fraction or tcfg.clean_weight == 1.0:
      return None
    c = self.problem.input_frames
    positions = self.put(batch.positions)
    window = positions[:, positions.shape[1] - c - 1:]
    clean = self._clean_windows(key, window, self.put(batch.moving))
    return jnp.where(clean, jnp.float32(tcfg.clean_weight), 1.0)

  def _push_forward(self, params, inputs, types, moving, solids, steps):
    """Inputs [B, C, N, 2] after ``steps`` learned steps from ``inputs``."""
    window = jnp.swapaxes(inputs, 0, 1)                   # [C, B, N, 2]
    positions, carried = self._roll(
        params, rollout_lib.SceneNodes(window, types, moving, solids), steps)
    frames = jnp.concatenate([window[:-1], carried, positions[-1:]], 0)
    return jnp.swapaxes(frames[-window.shape[0]:], 0, 1)

  def _roll(self, params, scene: rollout_lib.SceneNodes, steps: int):
    """(positions, carried) [steps, B, N, 2] of ``rollout.unroll`` without
    gradient, the pushforward neighbour list grown until it holds them."""
    spec, window = self.problem.spec, scene.window
    n = window.shape[2]
    nbrs = self._pushforward_nbrs.get(n)
    if nbrs is None:
      nbrs = self._allocate("pushforward", window[-1])
    while True:  # the overflow policy of gnsjax.graph: rerun, grown
      positions, carried, overflow, nbrs, _ = self._unroll(
          params, scene, nbrs, self.problem.context, spec=spec, length=steps,
          project=self.config.train.pushforward_constrained, batched=True)
      if not bool(jnp.any(overflow)):
        break
      # Size the list from every step's frames (the steps after an
      # overflow are only approximately right, hence the rerun).
      grown = False
      for frame in [window[-1]] + list(positions):
        nbrs, reallocated = graph.update_or_reallocate(spec, frame, nbrs,
                                                       batched=True)
        grown |= reallocated
      if not grown:
        raise RuntimeError("pushforward: the neighbour list overflowed, "
                           "yet holds every step's edges")
    self._pushforward_nbrs[n] = nbrs
    return positions, carried

  def train_unrolled(self, state: TrainState, batch: batching.Batch,
                     key: jax.Array, steps: int):
    """One step on the ``steps``-step loss (``gnsjax.unrolled``) from the
    batch's last C + ``steps`` frames, noisy as ``batch_arrays``'s; a
    neighbour list that overflows is sized by a rollout and the step
    rerun from the same state. Returns (state, metrics)."""
    put, c = self.put, self.problem.input_frames
    positions, moving = put(batch.positions), put(batch.moving)
    solids = mpm_geometry.SDFGrid(put(batch.solids), self.problem.sdf_spacing)
    start = positions.shape[1] - c - steps
    inputs, _ = self.prepare(key, positions[:, start:start + c + 1], moving,
                             solids)
    offset = inputs[:, -1] - positions[:, start + c - 1]
    truth = unrolled.truth_frames(self._shift_target, positions, offset,
                                  moving, solids, start + c, steps)
    scene = rollout_lib.SceneNodes(jnp.swapaxes(inputs, 0, 1),
                                   put(batch.particle_type), moving, solids)
    nbrs = self._pushforward_nbrs.get(positions.shape[2])
    if nbrs is not None:
      new, metrics, overflow = self._unrolled_step(state, scene, truth, nbrs)
      if not bool(overflow):
        return new, metrics
    self._roll(state.params, scene, steps)
    new, metrics, overflow = self._unrolled_step(
        state, scene, truth, self._pushforward_nbrs[positions.shape[2]])
    if bool(overflow):
      raise RuntimeError("unrolled training: the neighbour list overflowed, "
                         "yet holds the rollout's edges")
    return new, metrics


@functools.partial(jax.jit, static_argnums=1)
def _batched_edges(nbrs, n):
  return jax.vmap(lambda nb: graph.edges(nb, n))(nbrs)


def _windows(dataset: data.WindowDataset, step: int, batch_size: int,
             rows: range | None = None):
  """The windows of batch ``step`` (only ``rows`` of it, if given)."""
  rows = range(batch_size) if rows is None else rows
  return [dataset[step * batch_size + i] for i in rows]


def train_and_evaluate(config: ml_collections.ConfigDict, data_dir: str,
                       workdir: str) -> dict:
  """Trains (or resumes) in ``workdir``; returns the last metrics.

  Across processes (after ``gnsjax.distributed.initialize``) every process
  calls it with the same arguments; ``workdir`` and ``data_dir`` must be on
  a filesystem they share.
  """
  config_lib.check_config(config)
  distributed.check_supported(config, jax.process_count())
  os.makedirs(workdir, exist_ok=True)
  cfg, tcfg = config, config.train
  if tcfg.batch_size % jax.device_count():
    raise InputError(f"train.batch_size = {tcfg.batch_size} must be a "
                     f"multiple of the {jax.device_count()} devices")
  lead = jax.process_index() == 0  # writes the logs
  if jax.process_count() == 1:
    # Resume from the newest intact checkpoint, never a damaged one.
    checkpoint.set_aside_damaged(workdir)
  mngr = checkpoint.manager(workdir, cfg.checkpoint.every_steps,
                            cfg.checkpoint.named_steps, cfg.checkpoint.keep)
  config_dict = config_lib.config_dict(config)
  stored = None
  if mngr.latest_step() is not None:
    config_lib.check_compatible(
        checkpoint.read_config(mngr, mngr.latest_step()), config)
    stored = checkpoint.read_stats(mngr, mngr.latest_step())
  start_from = None
  if stored is None and tcfg.init_from:
    start_from = run_lib.load_run(tcfg.init_from)
    config_lib.check_fine_tuning(start_from.config.to_dict(), config)
    stored = run_lib.fine_tuning_problem(start_from, config).to_dict()
  # A resumed (or fine-tuned) model keeps the statistics it was trained with
  # (a fine-tuning takes its noise from the config).
  problem = (run_lib.problem_from_dict(config, stored) if stored is not None
             else run_lib.load_problem(data_dir, config))
  trainer = Trainer(config, problem)
  state = trainer.init_state(tcfg.seed)
  if start_from is not None:
    state = trainer.replicate(state.replace(params=run_lib.fine_tuning_params(
        start_from.params, state.params)))
    logging.info("fine-tuning from %s, step %d", tcfg.init_from,
                 start_from.step)
  elif stored is not None:
    state, _, _ = checkpoint.restore(mngr, state)
    trainer.restore_graph_capacities(
        checkpoint.read_graph_capacities(mngr, int(state.step)))
    state = trainer.replicate(state)
    logging.info("resumed from step %d", int(state.step))
  if lead:
    mpm_io.write_json(os.path.join(workdir, "config.json"), config_dict)
    mpm_io.write_json(os.path.join(workdir, "stats.json"), problem.to_dict())

  # At probability 0 pushforward is off: the windows (and so the stream of
  # examples and the losses) are those of a run without it.
  pushforward = (tcfg.pushforward_steps if tcfg.pushforward_probability > 0
                 else 0)
  unroll = tcfg.unroll_steps if tcfg.unroll_probability > 0 else 0
  extra = max(pushforward, unroll - 1)  # frames beyond C + 1 per window
  dataset = data.WindowDataset(data.split_path(data_dir, "train"),
                               input_frames=tcfg.input_frames + extra,
                               seed=tcfg.seed,
                               frame_stride=tcfg.frame_stride,
                               motion_weighting=tcfg.motion_weighting)
  device_windows = None
  if tcfg.device_windows:
    if problem.boundary_particles:
      raise InputError("config.train.device_windows = True needs "
                       "config.model.boundary_particles = False (boundary "
                       "particles are chosen per window on the host)")
    device_windows = batching.DeviceWindows(
        data.split_path(data_dir, "train"), problem.spec,
        input_frames=tcfg.input_frames + extra,
        frame_stride=tcfg.frame_stride, node_bucket=tcfg.node_bucket,
        sdf_spacing=problem.sdf_spacing)
  writer = (tensorboardX.SummaryWriter(os.path.join(workdir, "tensorboard"))
            if lead else None)
  csv_path = os.path.join(workdir, "metrics.csv")
  schedule = optimizer_lib.learning_rate_schedule(
      tcfg.lr_init, tcfg.lr_min, tcfg.lr_decay_steps)
  start = int(state.step)
  metrics = {}
  # The logged training time is process 0's (the others read its log).
  trained_before = (checkpoint.resume_metrics_csv(csv_path, start) if lead
                    else 0.0)
  trained_before = distributed.from_process_0(trained_before)
  run_start = last_time = time.perf_counter()
  last_step = start
  rows = trainer.rows(tcfg.batch_size)
  with (open(csv_path, "a", newline="") if lead else
        contextlib.nullcontext()) as csv_file, tqdm.tqdm(
            initial=start, total=tcfg.num_steps, unit="step",
            disable=not lead) as bar:
    out = None
    if lead:
      out = csv.DictWriter(csv_file, fieldnames=checkpoint.METRICS_FIELDS,
                           extrasaction="ignore")
      if csv_file.tell() == 0:
        out.writeheader()
    for step in range(start, tcfg.num_steps):
      if device_windows is not None:
        where = np.array([dataset.locate(step * tcfg.batch_size + i)
                          for i in range(tcfg.batch_size)])
        batch = device_windows.batch(where[:, 0], where[:, 1])
      else:
        batch = trainer.make_batch(_windows(dataset, step, tcfg.batch_size,
                                            rows))
      unrolled_now, push, rest = batch_kinds.choose(
          tcfg, step, unroll, pushforward,
          functools.partial(batch_kinds.any_still, batch, tcfg))
      key = jax.random.fold_in(state.key, step)
      if unrolled_now:
        state, step_metrics = trainer.train_unrolled(state, batch, key,
                                                     unrolled_now)
      else:
        graphs, target = trainer.batch_arrays(
            batch, key, params=state.params, pushforward=push,
            rest_pushforward=rest)
        weights = None if push else trainer.window_weights(batch, key)
        state, step_metrics = trainer.train_step(state, graphs, target,
                                                 weights)
      done = step + 1
      loss = float(step_metrics["loss"])
      if not math.isfinite(loss):
        # Nothing of this step or later is saved: the latest checkpoint
        # keeps the last finite parameters.
        mngr.wait_until_finished()
        raise DivergedError(
            f"{workdir}: the training loss is {loss} at step {done}; "
            f"stopped, the latest checkpoint (step {mngr.latest_step()}) "
            "holds the last finite parameters (a lower "
            "config.train.lr_init or clip_norm may help)")
      if done % cfg.log_every == 0 or done == tcfg.num_steps:
        now = time.perf_counter()
        metrics = {k: float(v) for k, v in step_metrics.items()}
        metrics.update(learning_rate=float(schedule(step)),
                       steps_per_s=(done - last_step) / (now - last_time),
                       wall_time_s=trained_before + now - run_start)
        last_time, last_step = now, done
        if lead:
          out.writerow({"step": done, **metrics})
          csv_file.flush()
          for k in ("loss", "grad_norm", "learning_rate", "steps_per_s"):
            writer.add_scalar(f"train/{k}", metrics[k], done)
        bar.set_postfix(loss=f"{metrics['loss']:.4g}")
      bar.update(1)
      if cfg.eval.every_steps and (done % cfg.eval.every_steps == 0 or
                                   done == tcfg.num_steps):
        eval_metrics = train_eval.evaluate(
            trainer, state, data_dir, cfg.eval.num_windows,
            cfg.eval.rollout_steps, cfg.eval.num_rollouts)
        if lead:
          for k, v in eval_metrics.items():
            writer.add_scalar(k, v, done)
        logging.info("step %d: %s", done, eval_metrics)
        metrics.update(eval_metrics)
      out_of_time = bool(tcfg.max_wall_time_s and time.perf_counter() -
                         run_start + trained_before >= tcfg.max_wall_time_s)
      if tcfg.max_wall_time_s:
        # Clocks differ: all stop when process 0's budget is spent.
        out_of_time = distributed.from_process_0(out_of_time)
      checkpoint.save(mngr, done, state, config_dict, problem.to_dict(),
                      trainer.graph_capacities(),
                      force=done == tcfg.num_steps or out_of_time)
      if out_of_time:
        logging.info("stopping at step %d: max_wall_time_s = %s reached",
                     done, tcfg.max_wall_time_s)
        break
  if writer is not None:
    writer.close()
  dataset.close()
  mngr.close()
  return metrics
