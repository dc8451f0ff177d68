"""Unrolled training: a loss through K learned steps of the model's rollout.

The one-step loss (``simulator.loss``) fits each learned step to the data,
and pushforward shows the model its own drift without a gradient through
the steps. Here the gradient flows through K steps of the rollout itself
(``rollout.unroll``, the solid constraint included when the run's
pushforward uses it), so the parameters are fitted to where the rollout
lands after K steps, not only after one ("unrolled training": List et al.
2022, "Learned turbulence modelling with differentiable fluid solvers";
Stachenfeld et al. 2022, "Learned coarse models for efficient turbulence
simulation").

Shapes: C input frames, K unrolled steps, B windows, N nodes (padded).
"""

import jax
import jax.numpy as jnp
import optax

from gnsjax import graph
from gnsjax import rollout as rollout_lib
from gnsjax import simulator


def unrolled_loss(predictor, params, scene: rollout_lib.SceneNodes,
                  truth: jax.Array, nbrs, context: simulator.Context,
                  spec: graph.GraphSpec, project: bool):
  """The K-step loss of a batch and whether its neighbour list overflowed.

  Each step's positional error is divided by the acceleration std, so the
  first step's term is exactly ``simulator.loss`` (a position error of one
  learned step is its acceleration error); later terms hold the error the
  earlier steps carried on. Mean over the K steps, then over the windows.

  Args:
    predictor, params: the simulator (``simulator.ModelPredictor``).
    scene: window [C, B, N, 2] (noisy) input frames (m), types int32 [B, N],
      moving bool [B, N], the batched SDF grids.
    truth: [K, B, N, 2] the true frames after the window (m), moved by the
      inputs' noise as pushforward's target is (``simulator.shift_target``).
    nbrs: a batched neighbour list (``graph.allocate_batch``).
    project: apply the solid constraint after each step (static).

  Returns:
    (loss [], overflow bool []).
  """
  steps = truth.shape[0]
  positions, _, overflow, _, _ = rollout_lib.unroll(
      predictor, params, scene, nbrs, context, spec=spec, length=steps,
      project=project, batched=True)
  err = (positions - truth) / context.stats.acc_std[None, None, None]
  err = jnp.sum(err**2, -1) * scene.moving[None]                 # [K, B, N]
  count = jnp.maximum(jnp.sum(scene.moving, -1), 1)              # [B]
  per_window = jnp.sum(err, (0, 2)) / steps / count / 2
  return jnp.mean(per_window), jnp.any(overflow)


def make_train_step(predictor, tx: optax.GradientTransformation,
                    context: simulator.Context, spec: graph.GraphSpec,
                    project: bool):
  """A jitted ``(state, scene, truth, nbrs) -> (state, metrics, overflow)``.

  The state is not donated: a step whose neighbour list overflowed is
  discarded and rerun from the same state with a grown list.
  """
  def train_step(state, scene, truth, nbrs):
    loss_fn = lambda p: unrolled_loss(predictor, p, scene, truth, nbrs,
                                      context, spec, project)
    (loss, overflow), grads = jax.value_and_grad(loss_fn, has_aux=True)(
        state.params)
    updates, opt_state = tx.update(grads, state.opt_state, state.params)
    params = optax.apply_updates(state.params, updates)
    state = state.replace(step=state.step + 1, params=params,
                          opt_state=opt_state)
    return state, {"loss": loss,
                   "grad_norm": optax.tree.norm(grads)}, overflow
  return jax.jit(train_step)


def truth_frames(shift_target, positions: jax.Array, offset: jax.Array,
                 moving: jax.Array, solids, start: int, steps: int):
  """[K, B, N, 2]: the frames ``start`` .. ``start + K - 1`` of
  ``positions`` [B, T, N, 2], each moved by ``offset`` [B, N, 2] (the last
  input frame's noise) with ``shift_target`` (batched)."""
  return jnp.stack([shift_target(positions[:, start + k], offset, moving,
                                 solids) for k in range(steps)], 0)
