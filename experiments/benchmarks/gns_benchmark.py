"""GNS benchmark: forward and training step, peers, FLOP rate, split layer.

  python -m experiments.benchmarks --what=gns --out=docs/benchmarks \
      --sand_block_dir=DIR

One library call, :func:`run_benchmark`, measures the learned simulator and
writes what it measured (``gns_benchmark.json`` and ``.md``) to a directory.
Its inputs are built in ``gns_inputs``, the programs it times in
``gns_programs``, its report in ``gns_report``. It measures:

1. the forward step (features + model: one call that turns a window of
   C = 6 input frames into normalised accelerations) and the training step
   (forward + backward of ``gnsjax.simulator.loss``, gradient clipping and
   Adam from ``gnsjax.optimizer.create_optimizer``) of the paper model
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

   The model sees the solids through the scene's signed distance field
   (``mpm.SDFGrid`` sampled at R / 6): node features [N, 2 (C - 1) + 3] =
   13, ten velocities and the SDF's clipped distance and weighted normal.
   The sand block has no scene of its own: it takes the SDF of the paper's
   default scene (``scenes.PAPER_SCENE``). Before the SDF features the
   model had 14 node features (the four distances to the box walls in
   place of the SDF's three), as in the figures recorded before them: the
   input layer lost one column (2 L FLOPs per node, under 0.01% of a
   forward) and the wall distances became a bilinear lookup in the grid,
   so those figures remain comparable. Every model is timed on the same
   graphs, boundary nodes included, although the small config's model now
   leaves boundary particles out (``model.boundary_particles``): the rows
   compare models, not training recipes.
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
import os
from typing import Any, Callable

import jax
import jax.numpy as jnp

from experiments import timing
from experiments.benchmarks import gns_inputs
from experiments.benchmarks import gns_programs
from experiments.benchmarks import gns_report
from experiments.benchmarks import op_profile


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


def _rate(flops, seconds):
  return None if flops is None else flops / seconds / 1e9


def _fraction(gflops, matmul):
  return None if gflops is None else gflops / matmul


def _row_flops(row: dict, runner: gns_programs.Runner) -> None:
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


def measure_model(name: str, g: gns_inputs.BenchGraph, sizes: Sizes,
                  matmul: gns_programs.Matmul,
                  log: Callable[[str], None], *, train_step: bool = True,
                  padded: bool = False) -> dict[str, Any]:
  """Items 1 and 3: forward (and training) step of one model on one graph,
  interleaved with the reference matmul."""
  config = gns_programs.load_config(name)
  runner = gns_programs.Runner(config, g, padded=padded)
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


def measure_split(name: str, g: gns_inputs.BenchGraph, sizes: Sizes,
                  matmul: gns_programs.Matmul,
                  log: Callable[[str], None]) -> dict[str, Any]:
  """Items 4 and 5: split first edge layer vs the concatenated form (same
  function), all four programs and the matmul interleaved; then where each
  program spends its time (``op_profile``)."""
  config = gns_programs.load_config(name)
  split_cfg = gns_programs.load_config(name)
  split_cfg.model.split_first_layer = True
  concat_cfg = gns_programs.load_config(name)
  concat_cfg.model.split_first_layer = False
  split = gns_programs.Runner(split_cfg, g)
  concat = gns_programs.Runner(
      concat_cfg, g, params=gns_programs.concat_params(split.params))
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
  out["forward_target_met"] = (out["forward_speedup"] >=
                               gns_report.TARGET_SPLIT_SPEEDUP)
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
    sand_block_dir: directory of the shared sand block window
      (``gns_inputs.load_sand_block``) and of the README quoting the peers.
    quick: tiny sizes (``QUICK``), seconds instead of minutes.
    log: called with one line per measurement.

  Returns:
    The results (the JSON's content) with the Markdown under "markdown".

  Raises:
    FileNotFoundError: a missing input file (named).
    ValueError: the README no longer quotes ``gns_report.PEERS``' times.
  """
  sizes = QUICK if quick else FULL
  # Inputs first: a bad directory fails now, not after minutes of timing.
  readme = os.path.join(sand_block_dir, gns_inputs.SAND_BLOCK_README)
  quotes = gns_report.check_quotes(readme)
  sand = gns_inputs.load_sand_block(sand_block_dir)
  results: dict[str, Any] = {"environment": timing.environment(quick),
                             "sizes": dataclasses.asdict(sizes)}
  matmul = gns_programs.Matmul(sizes.matmul_size)
  log(f"sand block: {sand.n_nodes} particles, {sand.n_edges} edges at R = "
      f"{sand.radius} (checked: {gns_inputs.SAND_BLOCK_EDGES}); solids: the "
      f"SDF of {sand.scene.name}")
  scene = gns_inputs.make_paper_scene(sizes.scene_frames, sizes.window_start)
  log(f"paper scene: frames {scene.info['frames'][0]}-"
      f"{scene.info['frames'][1]}, {scene.info['n_particles']} sand + "
      f"{scene.info['n_boundary']} boundary nodes, {scene.n_edges} edges")
  results["scenes"] = {g.name: {**g.info, **g.sdf_info,
                                "n_nodes": g.n_nodes,
                                "n_node_features":
                                    gns_programs.node_feature_size(),
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
