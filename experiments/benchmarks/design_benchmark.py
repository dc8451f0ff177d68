"""Inverse-design benchmark: what a gradient costs against the forward rollout.

  python -m experiments.benchmarks --what=design --out=docs/benchmarks

``run_benchmark(out_dir)`` measures, in one run on this machine, for the MPM
and the GNS on the small config's scene (250 particles, the shipped model)
and on a paper scene (1000 particles; the paper-sized GNS with untrained
weights, since cost does not depend on the weights):

- the forward rollout and the gradient of an objective with respect to the
  obstacle's x (rematerialised per step/frame), each compiled apart, warmed
  up and timed interleaved (``timing``: medians of repeats, seconds); their
  ratio (target: at most 4);
- the gradient program's memory as XLA allocates it (``memory_analysis``:
  temporaries, arguments, outputs; target: a paper scene within 2 GB), at
  the full 600 frames even where the timing uses fewer frames.

Writes ``design_benchmark.json`` and ``.md``.
"""

import json
import resource

import jax
import jax.numpy as jnp
import numpy as np

from experiments import tasks
from experiments.benchmarks import timing
from gnsjax import design
from gnsjax import evaluate
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import objectives
from gnsjax import train

GB = 1024**3
RATIO_TARGET = 4.0
MEMORY_TARGET_GB = 2.0


def _memory_gb(program: timing.Compiled) -> dict:
  """XLA's allocation for a compiled program (GB): temporaries, and all of
  temporaries + arguments + outputs."""
  m = program.executable.memory_analysis()
  total = (m.temp_size_in_bytes + m.argument_size_in_bytes +
           m.output_size_in_bytes)
  return {"temp_gb": m.temp_size_in_bytes / GB, "total_gb": total / GB}


def paper_gns(placement):
  """The paper-sized GNS (latent 128, 10 steps) with untrained weights."""
  model = models.EncodeProcessDecode(latent_size=128, hidden_layers=2,
                                     num_message_passing_steps=10,
                                     type_embedding_size=16)
  params = model.init(jax.random.key(0), jnp.zeros((4, 14)),
                      jnp.zeros(4, jnp.int32), jnp.zeros((4, 3)),
                      jnp.zeros(4, jnp.int32), jnp.zeros(4, jnp.int32))
  bounds = ((0.0, placement.scene.domain.width),
            (0.0, placement.scene.domain.height))
  # Tiny accelerations: the heap stays a heap, so the graph keeps the size
  # of a real paper scene's.
  stats = features.Stats(np.zeros(2, np.float32), np.full(2, 1e-3, np.float32),
                         np.zeros(2, np.float32), np.full(2, 1e-6, np.float32))
  problem = train.Problem(stats, np.asarray(bounds, np.float32), 0.015,
                          graph.GraphSpec(0.015, bounds))
  return model, params, problem


def _programs(sim, objective, remat: bool):
  """(forward, gradient, args, nodes) of a design rollout, freshly jitted.

  Fresh ``jax.jit`` objects each call: ``sim.num_frames`` is read at trace
  time, and a jitted function reused after changing it would return its
  cached trace of the old length.
  """
  params = sim.placement.initial()
  if isinstance(sim, design.GNSRollout):
    forward = jax.jit(lambda p, mp, nb: sim.positions(p, mp, nb,
                                                      remat=False)[0])
    grad = jax.jit(jax.grad(lambda p, mp, nb: objective(
        sim.positions(p, mp, nb, remat=remat)[0])))
    return forward, grad, (params, sim.model_params, sim.nbrs), len(sim.types)
  forward = jax.jit(lambda p: sim.positions(p, remat=False)[0])
  grad = jax.jit(jax.grad(lambda p: objective(
      sim.positions(p, remat=remat)[0])))
  return forward, grad, (params,), sim.setup.n_particles


def measure(name: str, sim, objective, timed_frames: int, full_frames: int,
            repeats: int, log, remat: bool = True) -> dict:
  """Forward rollout and gradient of one design rollout, timed interleaved
  over ``timed_frames`` frames; the gradient's memory at ``full_frames``.

  Returns:
    A row: seconds (``forward_s``, ``gradient_s``: medians), their ratio,
    compile seconds, and XLA memory in GB at ``memory_frames``.
  """
  forward, grad, args, nodes = _programs(sim, objective, remat)
  log(f"{name}: timing {timed_frames} frames")
  forward = timing.compile_program(forward, *args)
  grad = timing.compile_program(grad, *args)
  times = timing.time_calls({"forward": lambda: forward(*args),
                             "gradient": lambda: grad(*args)}, repeats)
  t_forward = times["forward"]["median_s"]
  t_grad = times["gradient"]["median_s"]
  row = {"case": name, "particles_or_nodes": nodes,
         "timed_frames": timed_frames, "forward_s": t_forward,
         "gradient_s": t_grad, "ratio": t_grad / t_forward,
         "compile_s": {"forward": forward.compile_s,
                       "gradient": grad.compile_s},
         "memory_frames": timed_frames, **_memory_gb(grad)}
  if full_frames != timed_frames:
    sim.num_frames = full_frames
    _, full_grad, args, _ = _programs(sim, objective, remat)
    row.update(memory_frames=full_frames,
               **_memory_gb(timing.compile_program(full_grad, *args)))
  log(json.dumps(row))
  return row


def run_benchmark(out_dir: str, *, quick: bool = False, repeats: int = 2,
                  log=print) -> dict:
  env = timing.environment(quick)
  frames = 20 if quick else 600
  paper_gns_frames = 12 if quick else 50
  objective = objectives.make("passed_fraction", x_protect=0.4).smooth
  small = tasks.design_scene("semicircle", (0.04,), 1.0, frames)
  paper = tasks.design_scene("semicircle", (0.04,), 1.0, frames,
                             spacing=0.005, num_particles=1000)
  rows = []
  rows.append(measure("MPM, small scene",
                      design.MPMRollout(design.Placement(small)), objective,
                      frames, frames, repeats, log))
  # Without remat: the recompute's share of the ratio (memory grows with
  # every substep's residuals).
  rows.append(measure("MPM, small scene, no remat",
                      design.MPMRollout(design.Placement(small)), objective,
                      frames, frames, repeats, log, remat=False))
  rows.append(measure("MPM, paper scene",
                      design.MPMRollout(design.Placement(paper)), objective,
                      frames, frames, repeats, log))
  config, problem, trainer, state, _ = evaluate.load_run(tasks.PRETRAINED,
                                                         scene=small)
  rows.append(measure(
      "GNS small model, small scene",
      design.GNSRollout(design.Placement(small), trainer.model, state.params,
                        problem, config.train.input_frames), objective,
      frames, frames, repeats, log))
  placement = design.Placement(paper)
  model, params, problem = paper_gns(placement)
  rows.append(measure(
      "GNS paper model, paper scene",
      design.GNSRollout(placement, model, params, problem, 6,
                        paper_gns_frames), objective,
      paper_gns_frames, frames, repeats, log))
  results = {"environment": env, "rows": rows,
             "peak_rss_gb": resource.getrusage(
                 resource.RUSAGE_SELF).ru_maxrss * 1024 / GB}
  timing.end_environment(env)
  timing.write_results(out_dir, "design_benchmark", quick, results,
                       markdown(results))
  return results


def markdown(results: dict) -> str:
  env = results["environment"]
  lines = [
      "# Inverse-design benchmark", "",
      f"`python -m experiments.benchmarks --what=design`, {env['date']}, "
      f"{env['cpu_count']} CPU cores, jax {env['jax_version']} "
      f"({env['jax_backend']}), load average at start "
      f"{env['load_average_start'][0]:.2f}.", "",
      f"Gradient of the passed fraction w.r.t. the obstacle's x, "
      f"rematerialised per step (GNS) or frame (MPM). Targets: gradient <= "
      f"{RATIO_TARGET:g}x the forward rollout; a paper scene's gradient "
      f"within {MEMORY_TARGET_GB:g} GB.", "",
      "| case | particles (MPM) / nodes (GNS) | frames timed | forward (s) | "
      "gradient (s) | gradient / forward | XLA memory of the gradient (GB) "
      "| at frames |", "|---|---|---|---|---|---|---|---|"]
  for r in results["rows"]:
    lines.append(
        f"| {r['case']} | {r['particles_or_nodes']} | {r['timed_frames']} | "
        f"{r['forward_s']:.3f} | {r['gradient_s']:.3f} | "
        f"**{r['ratio']:.2f}x** | {r['total_gb']:.3f} (temporaries "
        f"{r['temp_gb']:.3f}) | {r['memory_frames']} |")
  lines += ["", f"Peak resident memory of the whole benchmark process: "
            f"{results['peak_rss_gb']:.2f} GB."]
  return "\n".join(lines) + "\n"
