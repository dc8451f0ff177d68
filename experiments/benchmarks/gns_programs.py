"""The programs the GNS benchmark times, and their FLOPs.

``Runner`` compiles one model's forward step (``simulator.predict``,
features + model: a window of C = 6 input frames [C, N, 2] (m) and its
scene's SDF grid to normalised accelerations [N, 2]) and training step
(loss, gradient, clipping and Adam, batch 1) on one graph; ``dense_flops``
counts the FLOPs of their dense layers; ``Matmul`` is the machine's
reference rate that runs beside them.
"""

import importlib
import statistics
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import optax

from experiments import timing
from experiments.benchmarks import gns_inputs
from gnsjax import features
from gnsjax import models
from gnsjax import optimizer
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import train


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

  def rate(self, times: dict[str, Any]) -> dict[str, Any]:
    """GFLOP/s of a ``timing.time_calls`` summary of this matmul
    (recorded)."""
    rates = [self.flops / s / 1e9 for s in times["all_s"]]
    self.samples += rates
    return {"median_gflops": statistics.median(rates),
            "max_gflops": max(rates), "repeats": len(rates)}

  def summary(self) -> dict[str, Any]:
    return {"size": self.size, "flops": self.flops,
            "median_gflops": statistics.median(self.samples),
            "max_gflops": max(self.samples),
            "min_gflops": min(self.samples), "samples": len(self.samples)}


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


def node_feature_size() -> int:
  """F of the node features of a window of C = ``gns_inputs.INPUT_FRAMES``
  frames: 2 (C - 1) velocities and 3 of the scene's SDF
  (``features.num_node_features``)."""
  return features.num_node_features(gns_inputs.INPUT_FRAMES)


def init_params(model: models.EncodeProcessDecode, seed: int = 0):
  """Initial parameters (cost does not depend on their values)."""
  return models.init_params(model, jax.random.key(seed), node_feature_size())


def concat_params(params):
  """The concatenated-form parameters computing the same function."""
  mapped = dict(params["params"])
  for name in mapped:
    if name.startswith("step_"):
      mapped[name] = models.split_to_concat_params(mapped[name])
  return {"params": mapped}


def forward_fn(model, radius: float):
  """jit of ``simulator.predict``: (params, graph, context) -> normalised
  accelerations [N, 2] (graph: ``simulator.Graph``)."""
  def fn(params, graph, context):
    return simulator.predict(model, params, graph, context, radius)
  return jax.jit(fn)


def train_step_fn(model, tx, radius: float):
  """jit of one training step at batch 1 (``train.Trainer``'s, unbatched):
  loss and gradients of ``simulator.loss``, clipping and Adam (``tx``)."""
  def step(state, graph, target, context):
    def loss_fn(params):
      return simulator.loss(model, params, graph, target, context, radius)
    loss, grads = jax.value_and_grad(loss_fn)(state.params)
    updates, opt_state = tx.update(grads, state.opt_state, state.params)
    params = optax.apply_updates(state.params, updates)
    return state.replace(step=state.step + 1, params=params,
                         opt_state=opt_state), loss
  return jax.jit(step, donate_argnums=0)


class Runner:
  """Compiled forward and training step of one model on one graph.

  Args:
    config: an ``experiments/configs`` config (its ``model`` and ``train``).
    g: the window and graph.
    params: the model's parameters (default: initialised ones; cost does not
      depend on their values).
    padded: run on the neighbour list's padded capacity, as rollouts do,
      instead of exactly the graph's edges.

  The model sees the graph's SDF grid at the config's ``model.sdf_spacing``
  (unset: the grid ``gns_inputs`` built, at R / 6, the configs' default).

  ``compile_forward`` and ``compile_train`` compile (``fwd``, ``step``:
  ``timing.Compiled``); ``forward`` and ``train_step`` then run one call
  each (the training state is donated and replaced by the new one).
  """

  def __init__(self, config, g: gns_inputs.BenchGraph, params=None,
               padded: bool = False):
    self.model = run_lib.create_model(config.model)
    self.tx = optimizer.create_optimizer(config.train)
    self.params = init_params(self.model) if params is None else params
    s, r = ((g.padded_senders, g.padded_receivers) if padded
            else (g.senders, g.receivers))
    self.graph = g
    c = gns_inputs.INPUT_FRAMES
    solids = g.solids_at(config.model.sdf_spacing)
    self.inputs = simulator.Graph(
        jnp.asarray(g.positions[:c]), jnp.asarray(g.particle_type),
        jnp.asarray(g.moving), jnp.asarray(s), jnp.asarray(r),
        jax.tree.map(jnp.asarray, solids))
    self.fwd_args = (self.params, self.inputs, g.context)
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
    _, inputs, ctx = self.fwd_args
    target = jnp.asarray(g.positions[gns_inputs.INPUT_FRAMES])
    self.train_args = (inputs, target, ctx)
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
                       node_feature_size())
