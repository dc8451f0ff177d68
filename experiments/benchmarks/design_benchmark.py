"""Inverse-design benchmark: what a gradient costs against the forward rollout.

  python -m experiments.benchmarks --what=design --out=docs/benchmarks

``run_benchmark(out_dir)`` measures, in one run on this machine, for the MPM
and the GNS on the small config's scene (250 particles, the shipped model
``settings_lib.PRETRAINED``, loaded by ``rollouts.gns_driver``) and on a paper scene
(1000 particles; the paper-sized GNS of ``configs/paper.py`` with untrained
weights, since cost does not depend on the weights), each through the
``gnsjax.design`` rollouts (``mpm_positions``, ``gns_positions``: the
placement's boundary nodes and SDF grid, the solid constraint):

- the forward rollout and the gradient of an objective with respect to the
  obstacle's x (rematerialised per step/frame), each compiled apart, warmed
  up and timed interleaved (``timing``: medians of repeats, seconds); their
  ratio (target: at most 4);
- the gradient program's memory as XLA allocates it (``memory_analysis``:
  temporaries, arguments, outputs; target: a paper scene within 2 GB), at
  the full 600 frames even where the timing uses fewer frames.

Frames are stored frames (0.0025 s each). The GNS takes a learned step
every ``frame_stride`` of them after its input frames (the shipped small
model: 3, the paper model: 1), so ``timed_steps`` records the steps each
row ran.

Writes ``design_benchmark.json`` and ``.md``.
"""

import functools
import json
import resource

import jax

from experiments.studies import settings as settings_lib
from experiments import timing
from experiments.configs import paper as paper_config
from gnsjax import design
from gnsjax import features
from gnsjax import models
from gnsjax import train
from gnsjax.design import objectives
from gnsjax.design import rollouts
from gnsjax.design import scenes

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


def untrained_gns(placement: design.Placement, config):
  """A GNS of ``config`` (``experiments/configs``) with untrained weights,
  and its problem on the placement's domain: (model, params, problem)."""
  model = train.create_model(config.model)
  params = models.init_params(
      model, jax.random.key(0),
      features.num_node_features(config.train.input_frames))
  domain = placement.scene.domain
  # Tiny accelerations: the heap stays a heap, so the graph keeps the size
  # of a real paper scene's.
  stored = {"vel_mean": [0.0, 0.0], "vel_std": [1e-3, 1e-3],
            "acc_mean": [0.0, 0.0], "acc_std": [1e-6, 1e-6],
            "bounds": [[0.0, domain.width], [0.0, domain.height]],
            "radius": config.dataset.connectivity_radius, "noise_std": 0.0}
  return model, params, train.problem_from_dict(config, stored)


def paper_gns(placement: design.Placement):
  """The paper-sized GNS (``configs/paper.py``: latent 128, 10 steps, stride
  1, boundary particles) with untrained weights: (model, params, problem)."""
  return untrained_gns(placement, paper_config.get_config())


@functools.partial(jax.jit, static_argnames="remat")
def _gns_forward(sim, params, model_params, nbrs, remat=False):
  return design.gns_positions(sim, params, model_params, nbrs, remat=remat)


@functools.partial(jax.jit, static_argnames=("objective", "remat"))
def _gns_gradient(sim, params, model_params, nbrs, objective, remat=True):
  return jax.grad(lambda p: objective(design.gns_positions(
      sim, p, model_params, nbrs, remat=remat)[0]))(params)


@functools.partial(jax.jit, static_argnames="remat")
def _mpm_forward(sim, params, remat=False):
  return design.mpm_positions(sim, params, remat=remat)[0]


@functools.partial(jax.jit, static_argnames=("objective", "remat"))
def _mpm_gradient(sim, params, objective, remat=True):
  return jax.grad(lambda p: objective(design.mpm_positions(
      sim, p, remat=remat)[0]))(params)


def _programs(driver, sim, objective, remat: bool):
  """(forward, gradient, args, nodes, steps) of a design rollout.

  forward and gradient: (jitted function, its static keyword arguments).
  ``sim`` is a jit argument whose settings (``num_frames``, ...) are static,
  so a rollout of another length (``sim.replace(num_frames=n)``) is traced
  and compiled anew. The GNS's model parameters and neighbour list are the
  driver's. Steps: the GNS's learned steps, or the MPM's frames after the
  first.
  """
  params = sim.placement.initial()
  if isinstance(driver, design.GNSDriver):
    return ((_gns_forward, {"remat": False}),
            (_gns_gradient, {"objective": objective, "remat": remat}),
            (sim, params, driver.model_params, driver.nbrs), len(sim.types),
            sim.n_steps)
  return ((_mpm_forward, {"remat": False}),
          (_mpm_gradient, {"objective": objective, "remat": remat}),
          (sim, params), sim.n_particles, sim.num_frames - 1)


def _compile(program, args) -> timing.Compiled:
  fn, static = program
  return timing.compile_program(fn, *args, **static)


def _fit_graph(driver: design.GNSDriver, program, args):
  """Compiles the GNS's forward ``program`` on ``args``; if its neighbour
  list overflows in the rollout, lets the driver grow the list (its own
  ``rollout``) and compiles again for the larger one. Returns (compiled,
  args)."""
  sim, params = args[:2]
  compiled = _compile(program, args)
  if bool(compiled(*args)[1]):
    driver.rollout(params)
    args = (sim, params, driver.model_params, driver.nbrs)
    compiled = _compile(program, args)
  return compiled, args


def measure(name: str, driver, objective, timed_frames: int,
            full_frames: int, repeats: int, log, remat: bool = True) -> dict:
  """Forward rollout and gradient of one design rollout, timed interleaved
  over ``timed_frames`` frames; the gradient's memory at ``full_frames``.

  Args:
    name: the row's label.
    driver: a ``design.MPMDriver`` or ``design.GNSDriver``; its rollout is
      run for ``timed_frames`` frames (``sim.replace(num_frames=...)``).
    objective: a smooth objective of positions [T, N, 2] (static).
    timed_frames, full_frames: stored frames (the GNS's input frames
      included; it takes a learned step every ``frame_stride`` of them).
    repeats: timed rounds.
    log: called with progress and the row.
    remat: rematerialise each step or frame in the gradient.

  Returns:
    A row: seconds (``forward_s``, ``gradient_s``: medians), their ratio,
    compile seconds, steps timed, and XLA memory of the gradient in GB at
    ``memory_frames``.
  """
  sim = driver.sim.replace(num_frames=timed_frames)
  forward, grad, args, nodes, steps = _programs(driver, sim, objective,
                                                remat)
  log(f"{name}: timing {timed_frames} frames ({steps} steps)")
  if isinstance(driver, design.GNSDriver):
    forward, args = _fit_graph(driver, forward, args)
    forward_call = lambda: forward(*args)[0]
  else:
    forward = _compile(forward, args)
    forward_call = lambda: forward(*args)
  grad = _compile(grad, args)
  times = timing.time_calls({"forward": forward_call,
                             "gradient": lambda: grad(*args)}, repeats)
  t_forward = times["forward"]["median_s"]
  t_grad = times["gradient"]["median_s"]
  row = {"case": name, "particles_or_nodes": nodes,
         "timed_frames": timed_frames, "timed_steps": steps,
         "forward_s": t_forward, "gradient_s": t_grad,
         "ratio": t_grad / t_forward,
         "compile_s": {"forward": forward.compile_s,
                       "gradient": grad.compile_s},
         "memory_frames": timed_frames, **_memory_gb(grad)}
  if full_frames != timed_frames:
    full = driver.sim.replace(num_frames=full_frames)
    _, full_grad, full_args, _, _ = _programs(driver, full, objective, remat)
    row.update(memory_frames=full_frames,
               **_memory_gb(_compile(full_grad, full_args)))
  log(json.dumps(row))
  return row


def run_benchmark(out_dir: str, *, quick: bool = False, repeats: int = 2,
                  log=print) -> dict:
  env = timing.environment(quick)
  frames = 20 if quick else 600
  paper_gns_frames = 12 if quick else 50
  objective = objectives.make("passed_fraction", x_protect=0.4).smooth
  small = scenes.one_obstacle("semicircle", (0.04,), 1.0, frames)
  paper = scenes.one_obstacle("semicircle", (0.04,), 1.0, frames,
                              spacing=0.005, num_particles=1000)
  mpm_driver = lambda scene: design.MPMDriver(
      design.MPMRollout.create(design.Placement(scene)))
  rows = []
  rows.append(measure("MPM, small scene", mpm_driver(small), objective,
                      frames, frames, repeats, log))
  # Without remat: the recompute's share of the ratio (memory grows with
  # every substep's residuals).
  rows.append(measure("MPM, small scene, no remat", mpm_driver(small),
                      objective, frames, frames, repeats, log, remat=False))
  rows.append(measure("MPM, paper scene", mpm_driver(paper), objective,
                      frames, frames, repeats, log))
  rows.append(measure(
      "GNS small model, small scene",
      rollouts.gns_driver(design.Placement(small), settings_lib.PRETRAINED),
      objective, frames, frames, repeats, log))
  placement = design.Placement(paper)
  model, params, problem = paper_gns(placement)
  window = design.mpm_window(paper, problem.input_frames,
                             problem.frame_stride)
  rows.append(measure(
      "GNS paper model, paper scene",
      design.GNSDriver(design.GNSRollout.create(placement, model, problem,
                                                window), params),
      objective, paper_gns_frames, frames, repeats, log))
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
      "| case | particles (MPM) / nodes (GNS) | frames timed (steps) | "
      "forward (s) | gradient (s) | gradient / forward | XLA memory of the "
      "gradient (GB) | at frames |", "|---|---|---|---|---|---|---|---|"]
  for r in results["rows"]:
    steps = f" ({r['timed_steps']})" if "timed_steps" in r else ""
    lines.append(
        f"| {r['case']} | {r['particles_or_nodes']} | {r['timed_frames']}"
        f"{steps} | "
        f"{r['forward_s']:.3f} | {r['gradient_s']:.3f} | "
        f"**{r['ratio']:.2f}x** | {r['total_gb']:.3f} (temporaries "
        f"{r['temp_gb']:.3f}) | {r['memory_frames']} |")
  lines += ["", f"Peak resident memory of the whole benchmark process: "
            f"{results['peak_rss_gb']:.2f} GB."]
  return "\n".join(lines) + "\n"
