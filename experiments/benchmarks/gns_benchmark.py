"""GNS benchmark: forward and training step, peers, FLOP rate, split layer.

One library call, :func:`run_benchmark`, measures the learned simulator and
writes what it measured (JSON and Markdown) to a directory:

1. the forward step (features + model: one call that turns a window of
   C = 6 input frames into normalised accelerations) and the training step
   (forward + backward of ``gnsjax.simulator.loss``, gradient clipping and
   Adam from ``gnsjax.train.create_optimizer``) of the paper model
   (``configs/paper.py``) and the small model (``configs/small.py``), at batch
   1, on two graphs:

   * ``sand_block``: the shared sand block window (``--sand_block_dir``,
     kept outside the repository), 1000 sand particles, the graph public GNS
     implementations were timed on (24,930 directed edges at R = 0.015 m,
     self-pairs included; checked);
   * ``paper_scene``: frames 50-56 of the paper scene (one semicircle)
     simulated with ``mpm.simulate``, with all of its boundary (ramp and
     obstacle) particles as static nodes, as a rollout assembles them
     (``gnsjax.rollout.trajectory_nodes``), and statistics from its finite
     differences.

   The neighbour graph is computed before the clock starts (as geoelements/gns
   and LagrangeBench were timed) and holds exactly the graph's edges, no
   capacity padding; one more row times the paper model on the neighbour
   list's padded capacity, as rollouts run it.
2. peers, quoted in ``gns_report.PEERS`` from the window's README (not
   re-run; the README, where present, is checked to still quote them):
   geoelements/gns and LagrangeBench on the sand block; ours as a ratio.
3. this machine's matmul rate in the same run (jitted 2048x2048 float32
   matmuls, interleaved with every measurement above) and the model's
   achieved FLOP rate as a fraction of the rate measured beside it;
4. the split first edge layer against the concatenated form (same graph,
   same function: the concatenated parameters are mapped from the split ones
   with ``models.split_to_concat_params``), timed interleaved, with the FLOPs
   of each (``models.processor_flops`` and XLA's cost analysis);
5. where the time goes: the paper model's forward and training step (both
   forms) under ``jax.profiler``, operation time summed by kind (dense
   layers, gathers, scatters, reductions, elementwise; ``op_profile``).

Timing follows ``timing``'s rules: compilation (timed separately) and a
warm-up call are excluded; every call is waited on with
``jax.block_until_ready``; each figure is the median of repeats with the
minimum beside it. Calls measured together (forward, training step and the
matmul; split and concatenated forms) are interleaved, one call of each per
round, so that load from other processes falls on all of them alike.
"""

import dataclasses
import importlib
import json
import os
import statistics
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from experiments.benchmarks import scenes
from experiments.benchmarks import timing
from experiments.benchmarks import gns_report
from experiments.benchmarks import op_profile
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import rollout as rollout_lib
from gnsjax import simulator
from gnsjax import train
import mpm
from mpm import io as mpm_io

# The shared benchmark input: a directory (--sand_block_dir) holding these
# two files and the README that quotes the peers' times.
SAND_BLOCK_NPZ = "sand_block_window.npz"
SAND_BLOCK_METADATA = "sand_block_metadata.json"
SAND_BLOCK_README = "README.md"
SAND_BLOCK_EDGES = 24_930  # at R = 0.015 m, self-pairs included
INPUT_FRAMES = 6


@dataclasses.dataclass(frozen=True)
class Sizes:
  """What to measure, and how much.

  Attributes:
    models: configs (``experiments/configs/<name>.py``) timed on each scene.
    split_model: config of the split-vs-concatenated comparison (and of the
      padded-capacity row and the profile).
    repeats: timed rounds of each interleaved group (one forward, one
      training step, one matmul per round).
    matmul_size: n of the n x n float32 matmul that sets the machine's rate.
    scene_frames: frames simulated for the paper scene.
    window_start: first frame of its window (C + 1 frames from there).
    padded_row: also time the split model's forward on the padded capacity.
    profile_repeats: profiled calls of each program (item 5).
  """
  models: tuple[str, ...] = ("paper", "small")
  split_model: str = "paper"
  repeats: int = 7
  matmul_size: int = 2048
  scene_frames: int = 60
  window_start: int = 50
  padded_row: bool = True
  profile_repeats: int = 2


FULL = Sizes()
# Tiny sizes that exercise every measurement in seconds (smoke tests): the
# test config's model (latent 16, 2 steps), a short paper-scene simulation.
QUICK = Sizes(models=("test",), split_model="test", repeats=2,
              matmul_size=256, scene_frames=8, window_start=1,
              profile_repeats=1)


# ---------------------------------------------------------------- timing ---


class Matmul:
  """A jitted float32 ``size x size`` matmul of random matrices, the
  machine's reference rate; every timing group runs it beside its own
  calls, and ``samples`` collects each call's GFLOP/s (2 n^3 FLOPs)."""

  def __init__(self, size: int):
    ka, kb = jax.random.split(jax.random.key(0))
    self.size = size
    self.flops = 2.0 * size**3
    self._args = (jax.random.normal(ka, (size, size), jnp.float32),
                  jax.random.normal(kb, (size, size), jnp.float32))
    self._compiled = timing.compile_program(jax.jit(jnp.matmul), *self._args)
    self.samples: list[float] = []

  def __call__(self):
    return self._compiled(*self._args)

  def rate(self, timing: dict[str, Any]) -> dict[str, Any]:
    """GFLOP/s of a ``timing.time_calls`` summary of this matmul
    (recorded)."""
    rates = [self.flops / s / 1e9 for s in timing["all_s"]]
    self.samples += rates
    return {"median_gflops": statistics.median(rates),
            "max_gflops": max(rates), "repeats": len(rates)}

  def summary(self) -> dict[str, Any]:
    return {"size": self.size, "flops": self.flops,
            "median_gflops": statistics.median(self.samples),
            "max_gflops": max(self.samples),
            "min_gflops": min(self.samples), "samples": len(self.samples)}


# ---------------------------------------------------------------- inputs ---


@dataclasses.dataclass(frozen=True)
class BenchGraph:
  """One window and its radius graph.

  Attributes:
    name: scene name.
    positions: float32 [C + 1, N, 2] (m): C inputs, then the target.
    particle_type: int32 [N]; moving: bool [N].
    stats: normalisation statistics; bounds: [2, 2] (m); radius: R (m).
    senders, receivers: int32 [E], the graph's edges (no padding).
    padded_senders, padded_receivers: int32 [capacity], the neighbour list's
      edges with padding entries equal to N (as rollouts use them).
    info: what to record about the scene.
  """
  name: str
  positions: np.ndarray
  particle_type: np.ndarray
  moving: np.ndarray
  stats: features.Stats
  bounds: np.ndarray
  radius: float
  senders: np.ndarray
  receivers: np.ndarray
  padded_senders: np.ndarray
  padded_receivers: np.ndarray
  info: dict

  @property
  def n_nodes(self) -> int:
    return int(self.positions.shape[1])

  @property
  def n_edges(self) -> int:
    return int(self.senders.shape[0])

  @property
  def context(self) -> simulator.Context:
    return simulator.Context(
        features.Stats(*(jnp.asarray(s, jnp.float32) for s in self.stats)),
        jnp.asarray(self.bounds, jnp.float32))


def _radius_graph(last: np.ndarray, bounds: np.ndarray, radius: float):
  """(senders, receivers) without and with padding, from ``gnsjax.graph``."""
  spec = graph.GraphSpec(radius, tuple(map(tuple, np.asarray(
      bounds, np.float64).tolist())))
  n = last.shape[0]
  nbrs = graph.allocate(spec, jnp.asarray(last))
  if bool(nbrs.did_buffer_overflow):
    raise RuntimeError("neighbour list overflowed at allocation")
  senders, receivers = (np.asarray(a) for a in graph.edges(nbrs, n))
  real = senders < n
  return senders[real], receivers[real], senders, receivers


def sand_block_files(directory: str) -> list[str]:
  """The input files of the sand block window in ``directory``.

  Raises:
    FileNotFoundError: a missing input file (named).
  """
  paths = [os.path.join(directory, f) for f in (SAND_BLOCK_NPZ,
                                                 SAND_BLOCK_METADATA)]
  for path in paths:
    if not os.path.exists(path):
      raise FileNotFoundError(f"{path}: missing benchmark input (the shared "
                              "sand block window; see --sand_block_dir)")
  return paths


def load_sand_block(directory: str) -> BenchGraph:
  """The shared sand block window, its metadata and graph.

  Args:
    directory: holds ``sand_block_window.npz`` (positions float32
      [C + 1, N, 2] in m, particle_type int32 [N]) and
      ``sand_block_metadata.json`` (bounds, radius, statistics).

  Raises:
    FileNotFoundError: a missing input file (named).
    RuntimeError: the graph does not have the 24,930 edges the peers had.
  """
  npz, meta_path = sand_block_files(directory)
  with np.load(npz) as d:
    positions = np.asarray(d["positions"], np.float32)
    types = np.asarray(d["particle_type"], np.int32)
  with open(meta_path) as f:
    meta = json.load(f)
  if positions.shape[0] != INPUT_FRAMES + 1:
    raise ValueError(f"{npz}: positions {positions.shape}; want "
                     f"[{INPUT_FRAMES + 1}, N, 2]")
  radius = float(meta["default_connectivity_radius"])
  bounds = np.asarray(meta["bounds"], np.float32)
  stats = features.Stats(*(np.asarray(meta[k], np.float32) for k in
                           ("vel_mean", "vel_std", "acc_mean", "acc_std")))
  senders, receivers, ps, pr = _radius_graph(positions[INPUT_FRAMES - 1],
                                             bounds, radius)
  if len(senders) != SAND_BLOCK_EDGES:
    raise RuntimeError(
        f"sand block graph at R = {radius}: {len(senders)} edges, want "
        f"{SAND_BLOCK_EDGES} (the graph the peers were timed on)")
  moving = ~np.isin(types, mpm.KINEMATIC_TYPES)
  return BenchGraph(
      "sand_block", positions, types, moving, stats, bounds, radius, senders,
      receivers, ps, pr,
      {"source": npz, "n_particles": int(positions.shape[1]),
       "n_moving": int(moving.sum()), "n_boundary": 0,
       "edges_checked": SAND_BLOCK_EDGES})


def make_paper_scene(sizes: Sizes, radius: float = 0.015) -> BenchGraph:
  """Frames ``window_start``.. of the simulated paper scene, with all of its
  boundary particles as static nodes (``rollout.trajectory_nodes``)."""
  scene = mpm.Scene.from_dict({**scenes.PAPER_SCENE,
                               "num_frames": sizes.scene_frames})
  result = mpm.simulate(scene)
  t0 = sizes.window_start
  window = result.positions[t0:t0 + INPUT_FRAMES + 1]
  if window.shape[0] != INPUT_FRAMES + 1:
    raise ValueError(f"paper scene: {sizes.scene_frames} frames hold no "
                     f"window of {INPUT_FRAMES + 1} from frame {t0}")
  traj = mpm_io.Trajectory.from_result(result)
  traj = dataclasses.replace(traj, positions=window)
  positions, types, moving = rollout_lib.trajectory_nodes(
      traj, INPUT_FRAMES + 1)
  fd = mpm_io.finite_difference_stats([result.positions])
  stats = features.Stats(*(np.asarray(fd[k], np.float32) for k in
                           features.Stats._fields))
  bounds = np.array([[0.0, scene.domain.width], [0.0, scene.domain.height]],
                    np.float32)
  senders, receivers, ps, pr = _radius_graph(positions[INPUT_FRAMES - 1],
                                             bounds, radius)
  n_sand = int(result.positions.shape[1])
  return BenchGraph(
      "paper_scene", positions.astype(np.float32), types, moving, stats,
      bounds, radius, senders, receivers, ps, pr,
      {"scene": scene.to_dict(),
       "frames": [t0, t0 + INPUT_FRAMES], "n_particles": n_sand,
       "n_moving": int(moving.sum()),
       "n_boundary": int(positions.shape[1]) - n_sand,
       "stats": "finite differences of the simulated trajectory "
                f"({sizes.scene_frames} frames)"})


# ------------------------------------------------------------ the model ---


def load_config(name: str):
  return importlib.import_module(f"experiments.configs.{name}").get_config()


def _mlp_flops(rows: int, sizes: Sequence[int]) -> int:
  """2 x multiply-adds of dense layers sizes[0] -> sizes[1] -> ... on rows."""
  return 2 * rows * sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))


def dense_flops(model: models.EncodeProcessDecode, n_nodes: int,
                n_edges: int, node_features: int) -> dict[str, int]:
  """FLOPs of the model's dense layers: ``models.processor_flops`` plus the
  encoders and the decoder (2 per multiply-add)."""
  l, hl = model.latent_size, model.hidden_layers
  hidden = [l] * hl
  enc = (_mlp_flops(n_nodes, [node_features + model.type_embedding_size]
                    + hidden + [l]) +
         _mlp_flops(n_edges, [3] + hidden + [l]))
  dec = _mlp_flops(n_nodes, [l] + hidden + [model.output_size])
  proc = models.processor_flops(n_nodes, n_edges, l, hl,
                                model.num_message_passing_steps,
                                model.split_first_layer)
  return {"processor": proc, "encoders": enc, "decoder": dec,
          "total": proc + enc + dec}


def _node_feature_size() -> int:
  return 2 * (INPUT_FRAMES - 1) + 4


def init_params(model: models.EncodeProcessDecode, seed: int = 0):
  n, e = 8, 8
  return model.init(jax.random.key(seed),
                    jnp.zeros((n, _node_feature_size())),
                    jnp.zeros((n,), jnp.int32), jnp.zeros((e, 3)),
                    jnp.zeros((e,), jnp.int32), jnp.zeros((e,), jnp.int32))


def concat_params(params):
  """The concatenated-form parameters computing the same function."""
  mapped = dict(params["params"])
  for name in mapped:
    if name.startswith("step_"):
      mapped[name] = models.split_to_concat_params(mapped[name])
  return {"params": mapped}


def forward_fn(model, radius: float):
  """jit of ``simulator.predict``: (params, inputs, types, senders,
  receivers, context) -> normalised accelerations [N, 2]."""
  def fn(params, inputs, particle_type, senders, receivers, context):
    return simulator.predict(model, params, inputs, particle_type, senders,
                             receivers, context, radius)
  return jax.jit(fn)


def train_step_fn(model, tx, radius: float):
  """jit of one training step at batch 1 (``train.Trainer``'s, unbatched):
  loss and gradients of ``simulator.loss``, clipping and Adam (``tx``)."""
  def step(state, inputs, target, particle_type, moving, senders, receivers,
           context):
    def loss_fn(params):
      return simulator.loss(model, params, inputs, target, particle_type,
                            moving, senders, receivers, context, radius)
    loss, grads = jax.value_and_grad(loss_fn)(state.params)
    updates, opt_state = tx.update(grads, state.opt_state, state.params)
    params = optax.apply_updates(state.params, updates)
    return state.replace(step=state.step + 1, params=params,
                         opt_state=opt_state), loss
  return jax.jit(step, donate_argnums=0)


class _Runner:
  """Compiled forward and training step of one model on one graph."""

  def __init__(self, config, g: BenchGraph, params=None, padded=False):
    self.model = train.create_model(config.model)
    self.tx = train.create_optimizer(config.train)
    self.params = init_params(self.model) if params is None else params
    s, r = ((g.padded_senders, g.padded_receivers) if padded
            else (g.senders, g.receivers))
    self.graph = g
    self.fwd_args = (self.params, jnp.asarray(g.positions[:INPUT_FRAMES]),
                     jnp.asarray(g.particle_type), jnp.asarray(s),
                     jnp.asarray(r), g.context)
    self.n_edges_computed = int(s.shape[0])

  def compile_forward(self):
    self.fwd = timing.compile_program(
        forward_fn(self.model, self.graph.radius), *self.fwd_args)
    self.fwd_compile_s, self.fwd_xla_flops = (self.fwd.compile_s,
                                              self.fwd.flops)

  def forward(self):
    return self.fwd(*self.fwd_args)

  def compile_train(self):
    g = self.graph
    _, inputs, types, s, r, ctx = self.fwd_args
    self.train_args = (inputs, jnp.asarray(g.positions[INPUT_FRAMES]), types,
                       jnp.asarray(g.moving), s, r, ctx)
    self.state = self._fresh_state()
    self.step = timing.compile_program(
        train_step_fn(self.model, self.tx, g.radius), self.state,
        *self.train_args)
    self.train_compile_s, self.train_xla_flops = (self.step.compile_s,
                                                  self.step.flops)

  def _fresh_state(self):
    params = jax.tree.map(jnp.array, self.params)  # a copy: state is donated
    return train.TrainState(jnp.zeros((), jnp.int32), params,
                            self.tx.init(params), jax.random.key(0))

  def train_step(self):
    self.state, loss = self.step(self.state, *self.train_args)
    return loss

  def dense_flops(self):
    return dense_flops(self.model, self.graph.n_nodes, self.n_edges_computed,
                       _node_feature_size())


def _rate(flops, seconds):
  return None if flops is None else flops / seconds / 1e9


def _fraction(gflops, matmul):
  return None if gflops is None else gflops / matmul


def _row_flops(row: dict, runner: _Runner) -> None:
  fwd_s = row["forward"]["median_s"]
  dense = runner.dense_flops()
  row["flops"] = {"forward_dense": dense, "forward_xla": runner.fwd_xla_flops}
  row["forward_gflops_dense"] = _rate(dense["total"], fwd_s)
  row["forward_gflops_xla"] = _rate(runner.fwd_xla_flops, fwd_s)
  if "train_step" in row:
    row["flops"]["train_xla"] = runner.train_xla_flops
    row["train_gflops_xla"] = _rate(runner.train_xla_flops,
                                    row["train_step"]["median_s"])


def _add_fractions(row: dict, matmul: float) -> None:
  """Achieved GFLOP/s as fractions of the interleaved matmul rate."""
  for key in ("forward_gflops_dense", "forward_gflops_xla",
              "train_gflops_xla"):
    if key in row:
      row[key.replace("gflops", "matmul_fraction")] = _fraction(row[key],
                                                                matmul)


def _model_info(name: str, config) -> dict[str, Any]:
  m = config.model
  return {"config": name, "latent_size": m.latent_size,
          "hidden_layers": m.hidden_layers,
          "num_message_passing_steps": m.num_message_passing_steps,
          "type_embedding_size": m.type_embedding_size,
          "split_first_layer": m.split_first_layer}


def measure_model(name: str, g: BenchGraph, sizes: Sizes, matmul: Matmul,
                  log: Callable[[str], None], *, train_step: bool = True,
                  padded: bool = False) -> dict[str, Any]:
  """Items 1 and 3: forward (and training) step of one model on one graph,
  interleaved with the reference matmul."""
  config = load_config(name)
  runner = _Runner(config, g, padded=padded)
  runner.compile_forward()
  row = {"model": _model_info(name, config), "scene": g.name,
         "n_nodes": g.n_nodes, "n_edges": g.n_edges,
         "n_edges_computed": runner.n_edges_computed, "padded": padded,
         "n_params": int(sum(x.size for x in jax.tree.leaves(runner.params))),
         "compile_s": {"forward": runner.fwd_compile_s}}
  calls = {"forward": runner.forward}
  if train_step:
    runner.compile_train()
    row["compile_s"]["train_step"] = runner.train_compile_s
    calls["train_step"] = runner.train_step
  calls["matmul"] = matmul
  times = timing.time_calls(calls, sizes.repeats)
  row["forward"] = times["forward"]
  row["matmul"] = matmul.rate(times["matmul"])
  label = (f"{name} model on {g.name} ({g.n_nodes} nodes, "
           f"{runner.n_edges_computed} edges"
           + (", padded capacity" if padded else "") + ")")
  log(f"{label}: forward step {row['forward']['median_s']:.3f} s (features "
      f"+ model, graph precomputed; median of {sizes.repeats}, min "
      f"{row['forward']['min_s']:.3f}; compile {runner.fwd_compile_s:.1f} s "
      "excluded)")
  if train_step:
    row["train_step"] = times["train_step"]
    row["train_over_forward"] = (row["train_step"]["median_s"] /
                                 row["forward"]["median_s"])
    log(f"{label}: training step {row['train_step']['median_s']:.3f} s "
        f"(loss + grad + clip + Adam; median of {sizes.repeats}, min "
        f"{row['train_step']['min_s']:.3f}; compile "
        f"{runner.train_compile_s:.1f} s excluded)")
  _row_flops(row, runner)
  _add_fractions(row, row["matmul"]["median_gflops"])
  log(f"{label}: {row['flops']['forward_dense']['total'] / 1e9:.2f} GFLOP "
      "in dense layers per forward (XLA counts "
      f"{gns_report.gflop(runner.fwd_xla_flops)}) -> "
      f"{row['forward_gflops_dense']:.1f} GFLOP/s = "
      f"{gns_report.pct(row['forward_matmul_fraction_dense'])} of the "
      f"{row['matmul']['median_gflops']:.1f} GFLOP/s of "
      f"{matmul.size}^2 matmuls interleaved with it (target "
      f"{gns_report.pct(gns_report.TARGET_MATMUL_FRACTION)})")
  return row


def measure_split(name: str, g: BenchGraph, sizes: Sizes, matmul: Matmul,
                  log: Callable[[str], None]) -> dict[str, Any]:
  """Items 4 and 5: split first edge layer vs the concatenated form (same
  function), all four programs and the matmul interleaved; then where each
  program spends its time (``op_profile``)."""
  config = load_config(name)
  split_cfg = load_config(name)
  split_cfg.model.split_first_layer = True
  concat_cfg = load_config(name)
  concat_cfg.model.split_first_layer = False
  split = _Runner(split_cfg, g)
  concat = _Runner(concat_cfg, g, params=concat_params(split.params))
  for r in (split, concat):
    r.compile_forward()
    r.compile_train()
  diff = float(jnp.max(jnp.abs(split.forward() - concat.forward())))
  out = {"model": _model_info(name, config), "scene": g.name,
         "n_nodes": g.n_nodes, "n_edges": g.n_edges,
         "max_abs_output_diff": diff}
  times = timing.time_calls({"split_forward": split.forward,
                      "concat_forward": concat.forward,
                      "split_train_step": split.train_step,
                      "concat_train_step": concat.train_step,
                      "matmul": matmul}, sizes.repeats)
  out["matmul"] = matmul.rate(times["matmul"])
  fwd = {k: times[f"{k}_forward"] for k in ("split", "concat")}
  trn = {k: times[f"{k}_train_step"] for k in ("split", "concat")}
  for key, runner in (("split", split), ("concat", concat)):
    dense = runner.dense_flops()
    out[key] = {"forward": fwd[key], "train_step": trn[key],
                "processor_flops": dense["processor"],
                "dense_flops": dense["total"],
                "xla_forward_flops": runner.fwd_xla_flops,
                "xla_train_flops": runner.train_xla_flops,
                "forward_gflops_dense": _rate(dense["total"],
                                              fwd[key]["median_s"]),
                "compile_s": {"forward": runner.fwd_compile_s,
                              "train_step": runner.train_compile_s}}
    out[key]["forward_matmul_fraction_dense"] = _fraction(
        out[key]["forward_gflops_dense"], out["matmul"]["median_gflops"])
  out["forward_speedup"] = (fwd["concat"]["median_s"] /
                            fwd["split"]["median_s"])
  out["train_step_speedup"] = (trn["concat"]["median_s"] /
                               trn["split"]["median_s"])
  out["processor_flops_ratio"] = (out["concat"]["processor_flops"] /
                                  out["split"]["processor_flops"])
  out["processor_flops_saved"] = (out["concat"]["processor_flops"] -
                                  out["split"]["processor_flops"])
  if out["split"]["xla_forward_flops"] and out["concat"]["xla_forward_flops"]:
    out["xla_forward_flops_saved"] = (out["concat"]["xla_forward_flops"] -
                                      out["split"]["xla_forward_flops"])
    out["xla_forward_flops_ratio"] = (out["concat"]["xla_forward_flops"] /
                                      out["split"]["xla_forward_flops"])
  out["target_speedup"] = gns_report.TARGET_SPLIT_SPEEDUP
  out["forward_target_met"] = out["forward_speedup"] >= gns_report.TARGET_SPLIT_SPEEDUP
  out["train_step_target_met"] = (out["train_step_speedup"] >=
                                  gns_report.TARGET_SPLIT_SPEEDUP)
  log(f"split vs concatenated first edge layer ({name} model on {g.name}, "
      f"interleaved; outputs agree to {diff:.2g}): forward "
      f"{fwd['split']['median_s']:.3f} s vs {fwd['concat']['median_s']:.3f} s"
      f" ({out['forward_speedup']:.2f}x), training step "
      f"{trn['split']['median_s']:.3f} s vs {trn['concat']['median_s']:.3f} s"
      f" ({out['train_step_speedup']:.2f}x; target "
      f"{gns_report.TARGET_SPLIT_SPEEDUP}x); processor FLOPs "
      f"{out['split']['processor_flops'] / 1e9:.2f} G vs "
      f"{out['concat']['processor_flops'] / 1e9:.2f} G "
      f"({out['processor_flops_ratio']:.2f}x); XLA forward FLOPs "
      f"{gns_report.gflop(out['split']['xla_forward_flops'])} G vs "
      f"{gns_report.gflop(out['concat']['xla_forward_flops'])} G")

  out["profile"] = {}
  for key, runner in (("split", split), ("concat", concat)):
    for program, compiled, call, flops in (
        ("forward", runner.fwd.executable, runner.forward,
         runner.dense_flops()["total"]),
        ("train_step", runner.step.executable, runner.train_step, None)):
      p = op_profile.breakdown(compiled, call, sizes.profile_repeats)
      out["profile"][f"{key}_{program}"] = p
      if "skipped" in p:
        log(f"profile of the {key} {program}: skipped ({p['skipped']})")
        continue
      if flops:
        p["dense_gflops"] = _rate(flops, p["seconds"]["dense"])
      log(f"profile of the {key} {program} ({name} on {g.name}; operation "
          f"time {p['total_s']:.3f} s): " + ", ".join(
              f"{k} {100 * v:.0f}%" for k, v in p["share"].items())
          + (f"; dense layers run at {p['dense_gflops']:.1f} GFLOP/s"
             if flops else ""))
  return out


def run_benchmark(out_dir: str, sand_block_dir: str, quick: bool = False,
                  log: Callable[[str], None] = print) -> dict[str, Any]:
  """Runs every measurement and writes ``gns_benchmark[_quick].{json,md}``.

  Args:
    out_dir: directory for the results (created if missing).
    quick: tiny sizes (``QUICK``), seconds instead of minutes.
    log: called with one line per measurement.
    sand_block_dir: directory of the shared sand block window
      (``load_sand_block``) and of the README quoting the peers.

  Returns:
    The results (the JSON's content) with the Markdown under "markdown".

  Raises:
    FileNotFoundError: a missing input file (named).
    ValueError: the README no longer quotes ``gns_report.PEERS``' times.
  """
  sizes = QUICK if quick else FULL
  # Inputs first: a bad directory fails now, not after minutes of timing.
  readme = os.path.join(sand_block_dir, SAND_BLOCK_README)
  quotes = gns_report.check_quotes(readme)
  sand = load_sand_block(sand_block_dir)
  results: dict[str, Any] = {"environment": timing.environment(quick),
                             "sizes": dataclasses.asdict(sizes)}
  matmul = Matmul(sizes.matmul_size)
  log(f"sand block: {sand.n_nodes} particles, {sand.n_edges} edges at R = "
      f"{sand.radius} (checked: {SAND_BLOCK_EDGES})")
  scene = make_paper_scene(sizes)
  log(f"paper scene: frames {scene.info['frames'][0]}-"
      f"{scene.info['frames'][1]}, {scene.info['n_particles']} sand + "
      f"{scene.info['n_boundary']} boundary nodes, {scene.n_edges} edges")
  results["scenes"] = {g.name: {**g.info, "n_nodes": g.n_nodes,
                                "n_edges": g.n_edges,
                                "edge_capacity": int(len(g.padded_senders)),
                                "radius": g.radius,
                                "bounds": g.bounds.tolist()}
                       for g in (sand, scene)}
  steps = []
  for name in sizes.models:
    for g in (sand, scene):
      steps.append(measure_model(name, g, sizes, matmul, log))
  if sizes.padded_row:
    steps.append(measure_model(sizes.split_model, sand, sizes, matmul, log,
                               train_step=False, padded=True))
  results["steps"] = steps
  paper_rows = [r for r in steps if r["model"]["config"] == "paper" and
                r["scene"] == "sand_block" and not r["padded"]]
  if paper_rows:
    row = paper_rows[0]
    results["peers"] = gns_report.compare_peers(row, quotes)
    results["peers"]["ours"] = {"forward_s": row["forward"]["median_s"],
                                "train_step_s": row["train_step"]["median_s"]}
    ref = results["peers"]["peers"][gns_report.REFERENCE_PEER]
    log(f"against {gns_report.REFERENCE_PEER} (quoted {ref['forward_s']} s / "
        f"{ref['train_step_s']} s): forward "
        f"{ref['forward_ratio']:.2f}x, training step "
        f"{ref['train_step_ratio']:.2f}x their time (target <= "
        f"{gns_report.TARGET_PEER_RATIO}: forward "
        f"{gns_report.met(results['peers']['forward_target_met'])}, training "
        f"{gns_report.met(results['peers']['train_step_target_met'])})")
  results["split"] = measure_split(sizes.split_model, sand, sizes, matmul,
                                   log)
  results["matmul"] = matmul.summary()
  log(f"matmul rate of this run: {results['matmul']['median_gflops']:.1f} "
      f"GFLOP/s (median of {results['matmul']['samples']} jitted "
      f"{sizes.matmul_size}^2 float32 matmuls, interleaved with the above)")
  timing.end_environment(results["environment"])
  timing.write_results(out_dir, "gns_benchmark", quick, results,
                       gns_report.to_markdown(results))
  return results
