"""What message-passing depth and the connectivity radius cost a rollout.

Two measurements on test trajectories 0-2 of data/small1000 (175, 250 and
375 particles), each timed by the project's rules (``experiments.timing``:
a warm-up, the variants interleaved, medians of ``--repeats``):

``--mode=padded``: free rollouts (solid constraint on) of the shipped model
and of the same model padded to 10 message-passing steps, the five added
blocks outputting zero (their LayerNorms' scale and bias set to 0, so each
residual block is the identity). The predictions are the same, checked to
the bit; only the depth's cost differs.

``--mode=teacher``: one learned step (neighbour update, features, network,
constraint) along the MPM's own frames, for each (M, R) of ``--variants``,
so that every variant sees the same densities whatever its weights (fresh
ones). Edge capacity: the densest sampled frame's, on the rollouts' ladder.

  python docs/results/depth_cost.py --mode=padded \
      > docs/results/depth_cost/padded.md
  python docs/results/depth_cost.py --mode=teacher \
      > docs/results/depth_cost/teacher.md
"""
import copy
import functools

from absl import app
from absl import flags
import jax
import jax.numpy as jnp
import numpy as np

from experiments import timing
from gnsjax import data
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import rollout
from gnsjax import run as run_lib
from gnsjax import simulator

_MODE = flags.DEFINE_enum("mode", "padded", ["padded", "teacher"],
                          "what to time (module docstring)")
_MODEL = flags.DEFINE_string("model", "experiments/pretrained/small",
                             "the 5-step model")
_REPEATS = flags.DEFINE_integer("repeats", 3, "timed calls per variant")
_VARIANTS = flags.DEFINE_list(
    "variants", ["5:0.03", "10:0.03", "10:0.02", "10:0.022", "8:0.025",
                 "10:0.025"],
    "--mode=teacher: M:R pairs (message-passing steps, connectivity radius "
    "in m); the first is the reference of the ratio column")


def _parse_variants(items) -> tuple[tuple[int, float], ...]:
  """((M, R), ...) from ["M:R", ...]; a clear error on a malformed item."""
  out = []
  for item in items:
    try:
      m, r = item.split(":")
      out.append((int(m), float(r)))
    except ValueError:
      raise ValueError(f"--variants: {item!r} is not M:R, e.g. 5:0.03") \
          from None
  return tuple(out)


def _deeper(run, steps: int):
  """(model, params): ``run``'s model with ``steps`` message-passing steps,
  the added blocks copies of the first ones whose MLPs output zero."""
  cfg = copy.deepcopy(run.config.model)
  cfg.num_message_passing_steps = steps
  params = dict(run.params["params"])
  old = run.config.model.num_message_passing_steps
  for k in range(old, steps):
    block = jax.tree.map(np.array, params[f"step_{k % old}"])
    for mlp in ("edge_mlp", "node_mlp"):
      block[mlp]["norm"] = jax.tree.map(np.zeros_like, block[mlp]["norm"])
    params[f"step_{k}"] = block
  return run_lib.create_model(cfg), {"params": params}


def _padded(run, trajectories):
  deep, deep_params = _deeper(run, 10)
  print("| scene | particles | 5 steps (s) | padded to 10 (s) | ratio |")
  print("|---|---:|---:|---:|---:|")
  for t in trajectories:
    calls = {
        "m5": lambda t=t: rollout.rollout_trajectory(
            run.model, run.params, t, run.problem).positions,
        "m10": lambda t=t: rollout.rollout_trajectory(
            deep, deep_params, t, run.problem).positions}
    a, b = calls["m5"](), calls["m10"]()
    if not np.array_equal(np.asarray(a), np.asarray(b)):
      raise AssertionError(f"{t.scene.name}: the padded model predicts "
                           "differently")
    f = {k: v["median_s"] for k, v in
         timing.time_calls(calls, _REPEATS.value).items()}
    print(f"| {t.scene.name} | {t.positions.shape[1]} | {f['m5']:.2f} | "
          f"{f['m10']:.2f} | {f['m10'] / f['m5']:.2f} |", flush=True)


def _teacher_windows(t, c: int, k: int) -> np.ndarray:
  """[S, C, N, 2]: the input window of every learned step of ``t``, as a
  rollout started at each step's first input frame would see it."""
  pos = np.asarray(t.positions, np.float32)
  starts = rollout.predicted_frame_indices(len(pos), c, k) - c * k
  return np.stack([pos[s + rollout.input_frame_indices(c, k)]
                   for s in starts])


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _teacher_steps(predictor, spec, radius, params, windows, scene_arrays,
                   context, nbrs):
  """Sum of every step's prediction along ``windows`` [S, C, N, 2] (so the
  work is not optimised away) and whether the edges ever overflowed."""
  types, moving, solids = scene_arrays

  def body(nb, w):
    nb = graph.update(spec, w[-1], nb)
    senders, receivers = graph.edges(nb, w.shape[-2])
    g = simulator.Graph(w, types, moving, senders, receivers, solids)
    nxt, _, _ = simulator.step(predictor, params, g, context, radius, True)
    return nb, (nxt.sum(), nb.did_buffer_overflow)

  _, (out, overflow) = jax.lax.scan(body, nbrs, windows)
  return out.sum(), jnp.any(overflow)


def _teacher(run, trajectories):
  prob = run.problem
  if prob.boundary_particles:
    raise ValueError(f"{_MODEL.value}: --mode=teacher times sand-only "
                     "graphs; this model has boundary particles")
  c, k = prob.input_frames, prob.frame_stride
  variants = _parse_variants(_VARIANTS.value)
  m0, r0 = variants[0]
  print("| scene | particles | M | R (m) | edge capacity | s / trajectory "
        f"| ratio to M={m0}, R={r0} |")
  print("|---|---:|---:|---:|---:|---:|---:|")
  for t in trajectories:
    scene = rollout.trajectory_nodes(t, c, k, prob.boundary_particles,
                                     prob.sdf_spacing)
    windows = jnp.asarray(_teacher_windows(t, c, k))
    scene_arrays = jax.tree.map(jnp.asarray,
                                (scene.types, scene.moving, scene.solids))
    calls, capacity = {}, {}
    for m, r in variants:
      cfg = copy.deepcopy(run.config.model)
      cfg.num_message_passing_steps = m
      model = run_lib.create_model(cfg)
      params = models.init_params(model, jax.random.key(1),
                                  features.num_node_features(c))
      spec = graph.GraphSpec(r, prob.spec.bounds,
                             prob.spec.capacity_multiplier)
      sizes = [graph.allocate(spec, windows[i, -1]).idx.shape[-1]
               for i in range(0, len(windows), 5)]
      densest = windows[5 * int(np.argmax(sizes)), -1]
      nbrs = graph.rounded_up(graph.allocate(spec, densest, extra_capacity=4))
      call = functools.partial(_teacher_steps,
                               simulator.ModelPredictor(model), spec, r,
                               params, windows, scene_arrays, prob.context,
                               nbrs)
      if bool(call()[1]):
        raise AssertionError(f"M={m} R={r}: the edges overflowed")
      calls[(m, r)] = lambda call=call: call()[0]
      capacity[(m, r)] = nbrs.idx.shape[-1]
    f = {k: v["median_s"] for k, v in
         timing.time_calls(calls, _REPEATS.value).items()}
    for (m, r), s in f.items():
      print(f"| {t.scene.name} | {t.positions.shape[1]} | {m} | {r} | "
            f"{capacity[(m, r)]} | {s:.2f} | {s / f[variants[0]]:.2f} |",
            flush=True)


def main(argv):
  del argv
  run = run_lib.load_run(_MODEL.value)
  path = data.split_path("data/small1000", "test")
  trajectories = [t for i, t in enumerate(data.trajectories(path)) if i < 3]
  (_padded if _MODE.value == "padded" else _teacher)(run, trajectories)


if __name__ == "__main__":
  app.run(main)
