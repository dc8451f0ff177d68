"""The GPU command's report: the measured parts summed up against the
paper's figures and the targets (``summarise``), and written as Markdown
(``to_markdown``). Pure functions of the parts' JSON; the measuring is
``experiments.benchmarks.gpu_benchmark``'s (its parts ``gpu_mpm``,
``gpu_gns`` and ``gpu_train``).
"""

from typing import Any

from experiments.benchmarks import batch_benchmark

# The paper (Table 2, section III): a V100 for the GNS, its CPU for the MPM.
PAPER_GNS_S = (0.03, 0.05)
PAPER_MPM_S = (17.0, 23.0)
PAPER_TRAINING_H = {1_500_000: 81.5, 2_000_000: 134.0}
PAPER_DATASET = 1_100  # trajectories (1000 training, 100 test)

# The targets.
TARGET_PARTICLE_SUBSTEPS_PER_S = batch_benchmark.TARGET_PARTICLE_SUBSTEPS_PER_S
TARGET_GNS_CHEAPER_THAN_CPU_MPM = 10.0
TARGET_TRAINING_H = 24.0  # for 1.5 M steps

# Agreement (``gpu_benchmark``'s module docstring says why these).
AGREEMENT_EARLY_FRAME = 20
EARLY_TOLERANCE_M = 1e-5
FINAL_RMS_TOLERANCE_M = 1e-3
FINAL_MAX_TOLERANCE_M = 1e-2
FINAL_MEASURE_TOLERANCE_M = 1e-3
GNS_EARLY_STEP = 5


def _fmt(v, spec=".3g", none="-"):
  return none if v is None else format(v, spec)


def _ratio(a, b):
  return None if a is None or b is None or b == 0 else a / b


# -------------------------------------------------------------- summary ---


def _get(d, *keys):
  for k in keys:
    if d is None:
      return None
    d = d.get(k) if isinstance(d, dict) else None
  return d


def _rows_by(rows, key):
  return {r[key]: r for r in rows or []}


def summarise(parts: dict[str, dict], reference: dict | None
              ) -> dict[str, Any]:
  """The headline figures, the reference's beside them, and the targets."""
  ref = (reference or {}).get("parts", {})
  s: dict[str, Any] = {}
  m, rm = _get(parts, "mpm", "mpm"), ref.get("mpm")
  if m:
    best = max([r["particle_substeps_per_s"] for r in m.get("vmapped", [])]
               + [_get(m, "largest_batch", "particle_substeps_per_s") or 0])
    s["mpm"] = {
        "single_s": m["single"]["median_s"],
        "single_s_cpu": _get(rm, "single", "median_s"),
        "best_particle_substeps_per_s": best,
        "target_particle_substeps_per_s": TARGET_PARTICLE_SUBSTEPS_PER_S,
        "target_met": best >= TARGET_PARTICLE_SUBSTEPS_PER_S,
        "dataset_h": _get(m, "dataset", "dataset_h"),
        "dataset_h_cpu": _get(rm, "dataset", "dataset_h")}
  g, rg = _get(parts, "gns", "gns"), ref.get("gns")
  if g:
    rows = _rows_by(g["rollouts"], "batch")
    single = rows.get(1, {}).get("s_per_simulation")
    best = min(r["s_per_simulation"] for r in g["rollouts"])
    mpm_here = _get(s, "mpm", "single_s")
    mpm_cpu = (_get(rm, "single", "median_s") if reference else
               _get(s, "mpm", "single_s"))
    s["gns"] = {
        "single_s": single, "best_batched_s": best,
        "single_s_cpu": _get(_rows_by(_get(rg, "rollouts"), "batch"), 1,
                             "s_per_simulation"),
        "mpm_same_device_s": mpm_here, "mpm_cpu_s": mpm_cpu,
        "mpm_cpu_over_gns": _ratio(mpm_cpu, single),
        "mpm_same_device_over_gns": _ratio(mpm_here, single),
        "target_cheaper": TARGET_GNS_CHEAPER_THAN_CPU_MPM,
        "target_met": (None if mpm_cpu is None or single is None else
                       mpm_cpu / single >= TARGET_GNS_CHEAPER_THAN_CPU_MPM)}
  t, rt = _get(parts, "train", "train"), ref.get("train")
  if t:
    h = t["projected_h"]["1500000"]
    s["train"] = {"steps_per_s": t["steps_per_s"],
                  "steps_per_s_cpu": _get(rt, "steps_per_s"),
                  "projected_h": t["projected_h"],
                  "paper_h": {str(k): v for k, v in PAPER_TRAINING_H.items()},
                  "target_h": TARGET_TRAINING_H,
                  "target_met": h < TARGET_TRAINING_H}
  return s


# -------------------------------------------------------------- markdown ---


def _met(v):
  return "n/a" if v is None else ("**met**" if v else "**missed**")


def _x(a, b):
  """'a/b x' speed-up of b over a, or '-'."""
  r = _ratio(a, b)
  return "-" if r is None else f"{r:.3g}x"


def _env_line(env: dict | None) -> str:
  if not env:
    return "not available"
  return (f"{env.get('device_kind', '?')} ({', '.join(env['jax_devices'])}), "
          f"jax {env['jax_version']} on {env['jax_backend']}, "
          f"{env['platform']}, {env['cpu_count']} CPUs, load average "
          f"{env['load_average_start'][0]:.2f} at the start, {env['date']}")


def _agreement_lines(title: str, a: dict) -> list[str]:
  lines = [f"| {title} | early max (m) | final max (m) | final rms (m) | "
           "front (m) | centre x (m) | agrees |",
           "|---|---|---|---|---|---|---|"]
  for name, key in (("against the twin CPU, default precision", ("twin",
                                                                  "default")),
                    ("against the twin CPU, highest precision", ("twin",
                                                                  "highest")),
                    ("the twin CPU's own envelope (1 ulp)", ("twin",
                                                            "envelope")),
                    ("against the CPU reference", ("reference",)),
                    ("envelope here (1 ulp of the start)", ("envelope",))):
    c = _get(a, *key)
    if c is None:
      continue
    if "skipped" in c:
      lines.append(f"| {name} | - | - | - | - | - | not compared: "
                   f"{c['skipped']} |")
      continue
    if key == ("reference",) and title == "GNS":
      # Its precision is recorded since it was made "highest" (before:
      # the device's default).
      name += f", {c.get('precision', 'default')} precision"
    e, f = c["early"], c["final"]
    lines.append(f"| {name} | {e['max_m']:.2g} | {f['max_m']:.2g} | "
                 f"{f['rms_m']:.2g} | {f['front_1pct_m']:.2g} | "
                 f"{f['centre_x_m']:.2g} | "
                 + ("envelope" if "envelope" in key else
                    ("yes" if c["agrees"] else "**no**: " + ", ".join(
                        k for k, ok in c["checks"].items() if not ok)))
                 + " |")
  return lines + [""]


def to_markdown(report: dict, reference: dict | None) -> str:
  """The report as Markdown: every figure with the reference's beside it."""
  parts, s = report["parts"], report["summary"]
  ref = (reference or {}).get("parts", {})
  cpu = not report["accelerator"]
  quick = any(e.get("quick") for e in report["environments"].values())
  lines = ["# " + ("The GPU benchmark's programs on this CPU (reference)"
                   if cpu else "Accelerator benchmark: MPM, GNS, training, "
                   "agreement") + (" (quick: not figures)" if quick else ""),
           ""]
  for part, env in report["environments"].items():
    lines.append(f"- {part}: `{report['commands'][part]}`; "
                 f"{_env_line(env)}"
                 + ("" if report.get("complete", {}).get(part, True) else
                    "; **partial**: stopped before its end (a time limit),"
                    " only what it finished is below"))
  if not cpu:
    lines.append(f"- CPU reference (`{report['reference_file']}`): "
                 + _env_line(report.get("reference_environment")))
  lines += ["", "Compilation apart, a warm-up call, synchronised, medians "
            "of repeats. *Extrapolated*: fewer frames or steps were run and "
            "the time per substep or step scaled to the whole trajectory.",
            "", "CPU columns: the same code at the reference's sizes on "
            "this project's CPU; ratio = CPU time / this device's time."
            if not cpu else "", ""]
  m = _get(parts, "mpm")
  if m:
    rm = ref.get("mpm")
    sc = m["scene"]
    lines += [f"## MPM: the paper scene ({sc['n_particles']} particles, "
              f"{sc['frames']} frames, {sc['n_substeps_per_frame']} "
              "substeps per frame)", "",
              "| run | s per trajectory | particle-substeps/s | CPU s per "
              "trajectory | ratio |", "|---|---|---|---|---|"]
    single = m["single"]
    cpu_single = _get(rm, "single", "s_per_trajectory")
    lines.append(f"| one at a time (`mpm.simulate`) | "
                 f"{single['s_per_trajectory']:.4g} | "
                 f"{single['particle_substeps_per_s']:.3g} | "
                 f"{_fmt(cpu_single, '.4g')} | "
                 f"{_x(cpu_single, single['s_per_trajectory'])} |")
    rv = _rows_by(_get(rm, "vmapped"), "batch")
    for r in m.get("vmapped", []):
      c = _get(rv, r["batch"], "s_per_trajectory")
      lines.append(f"| vmapped x{r['batch']} | {r['s_per_trajectory']:.4g}"
                   + (" (extrapolated)" if r["extrapolated"] else "") +
                   f" | {r['particle_substeps_per_s']:.3g} | "
                   f"{_fmt(c, '.4g')} | {_x(c, r['s_per_trajectory'])} |")
    lb = m.get("largest_batch", {})
    if "batch" in lb:
      lines.append(f"| largest batch, x{lb['batch']} ({lb['frames'] - 1} "
                   f"frames) | {lb['s_per_trajectory']:.4g} (extrapolated)"
                   f" | {lb['particle_substeps_per_s']:.3g} | - | - |")
    sm = s["mpm"]
    lines.append("")
    if lb:
      lines.append(
          f"- Sizing (`batch_size_for`): "
          f"{lb['sizing']['batch']} scenes ({lb['sizing']['source']}; "
          f"{lb['sizing']['per_scene_bytes'] / 2**20:.2f} MiB per scene,"
          f" {lb['sizing']['fixed_bytes'] / 2**20:.2f} MiB fixed), run "
          f"at {lb.get('batch', 'none')} (cap {lb['cap']})"
          + (f"; out of memory at {[f['batch'] for f in lb['failed']]}"
             if lb["failed"] else "") + ".")
    lines += [f"- Target, batched MPM at least "
              f"{TARGET_PARTICLE_SUBSTEPS_PER_S:.0e} particle-substeps/s: "
              + ("not an accelerator" if cpu else
                 f"{_met(sm['target_met'])} (best "
                 f"{sm['best_particle_substeps_per_s']:.3g})") + "."]
    if "dataset" in m:
      lines += [f"- The paper's dataset ({PAPER_DATASET} trajectories of 600 "
              f"frames), simulation only, extrapolated from one batch of "
              f"{m['dataset']['batch']} of its scenes run for "
              f"{m['dataset']['frames_run']} frames: "
              f"**{m['dataset']['dataset_h']:.3g} h**"
              + (f" (CPU reference: {sm['dataset_h_cpu']:.3g} h)"
                 if sm.get("dataset_h_cpu") else "") + "."]
    lines.append("")
    if m.get("spacings"):
      rs = _rows_by(_get(rm, "spacings"), "spacing_m")
      lines += ["Speed/accuracy study's MPM rows (the paper scene at each "
                "spacing; errors: docs/tradeoff.md):", "",
                "| spacing (mm) | particles | s per trajectory | CPU | "
                "ratio |", "|---|---|---|---|---|"]
      for r in m["spacings"]:
        c = _get(rs, r["spacing_m"], "s_per_trajectory")
        lines.append(f"| {r['spacing_m'] * 1000:g} | {r['particles']} | "
                     f"{r['s_per_trajectory']:.4g} | {_fmt(c, '.4g')} | "
                     f"{_x(c, r['s_per_trajectory'])} |")
      lines.append("")
    lines += ["### Agreement of the paper scene with a CPU", "",
              f"Frames {m['agreement']['frames']}. Tolerances: early max "
              f"{EARLY_TOLERANCE_M:g} m; final rms {FINAL_RMS_TOLERANCE_M:g}"
              f" m, max {FINAL_MAX_TOLERANCE_M:g} m (one cell), front and "
              f"centre {FINAL_MEASURE_TOLERANCE_M:g} m (why: "
              "`experiments/benchmarks/gpu_benchmark.py`).", ""]
    lines += _agreement_lines("MPM", m["agreement"])
  g = _get(parts, "gns")
  if g:
    rg = ref.get("gns")
    sc, md = g["scene"], g["model"]
    lines += [f"## GNS: the {md['config']} model (latent "
              f"{md['latent_size']}, {md['num_message_passing_steps']} "
              f"steps) rolling out the paper trajectory ({sc['n_sand']} "
              f"sand + {sc['n_nodes'] - sc['n_sand']} boundary nodes, "
              f"{sc['learned_steps']} learned steps)", "",
              "| rollout | s per simulation | steps/s | CPU s per "
              "simulation | ratio |", "|---|---|---|---|---|"]
    rr = _rows_by(_get(rg, "rollouts"), "batch")
    for r in g["rollouts"]:
      c = _get(rr, r["batch"], "s_per_simulation")
      lines.append(f"| {'alone' if r['batch'] == 1 else 'x%d' % r['batch']}"
                   f" | {r['s_per_simulation']:.4g}"
                   + (" (extrapolated)" if r["extrapolated"] else "") +
                   f" | {r['steps_per_s']:.3g} | {_fmt(c, '.4g')}"
                   + (" (extrapolated)" if _get(rr, r["batch"],
                                                "extrapolated") else "") +
                   f" | {_x(c, r['s_per_simulation'])} |")
    sg = s["gns"]
    lines += ["", "Table 2 (seconds per simulation of a paper trajectory):",
              "", "| | this device | the paper |", "|---|---|---|",
              f"| GNS | {_fmt(sg['single_s'], '.4g')} alone, "
              f"{sg['best_batched_s']:.4g} batched | {PAPER_GNS_S[0]}-"
              f"{PAPER_GNS_S[1]} (V100) |",
              f"| MPM, same device | {_fmt(sg['mpm_same_device_s'], '.4g')}"
              f" | - |",
              f"| MPM, this project's CPU | {_fmt(sg['mpm_cpu_s'], '.4g')} "
              f"| {PAPER_MPM_S[0]:g}-{PAPER_MPM_S[1]:g} (its CPU) |", "",
              f"- MPM on the CPU / GNS alone: "
              f"{_fmt(sg['mpm_cpu_over_gns'], '.3g')}x (target at least "
              f"{TARGET_GNS_CHEAPER_THAN_CPU_MPM:g}x: "
              f"{_met(sg['target_met']) if not cpu else 'not an accelerator'}"
              f"); MPM on the same device / GNS alone: "
              f"{_fmt(sg['mpm_same_device_over_gns'], '.3g')}x.",
              f"- The model: {md['parameters']} (see the module docstring).",
              ""]
    sm = g.get("small_model")
    rsm = _get(rg, "small_model")
    if sm is not None:
      lines += [f"The shipped small model on its scene ({sm['particles']} "
                f"particles, {sm['steps']} steps of stride "
                f"{sm['frame_stride']}): {sm['s_per_simulation']:.4g} s per "
                "simulation"
                + (f" (CPU reference: {rsm['s_per_simulation']:.4g} s, "
                   f"{_x(rsm['s_per_simulation'], sm['s_per_simulation'])})"
                   if rsm else "") + ".", "",
                "### Agreement of the small model's rollout with a CPU", "",
                f"Steps {sm['agreement']['steps']}. Tolerances: early max "
                f"{EARLY_TOLERANCE_M:g} m; front and centre "
                f"{FINAL_MEASURE_TOLERANCE_M:g} m at the end (single "
                "particles are not compared there).", ""]
      lines += _agreement_lines("GNS", sm["agreement"])
  t = _get(parts, "train")
  if t:
    rt = ref.get("train")
    st = s["train"]
    lines += [f"## Training: the {t['config']} config (batch "
              f"{t['batch_size']}, latent {t['latent_size']}, "
              f"{t['num_message_passing_steps']} steps)", "",
              "| | steps/s | 1.5 M steps (h) | 2 M steps (h) |",
              "|---|---|---|---|",
              f"| this device | {t['steps_per_s']:.3g} | "
              f"{t['projected_h']['1500000']:.3g} | "
              f"{t['projected_h']['2000000']:.3g} |"]
    if rt:
      lines.append(f"| CPU reference | {rt['steps_per_s']:.3g} | "
                   f"{rt['projected_h']['1500000']:.3g} | "
                   f"{rt['projected_h']['2000000']:.3g} |")
    lines += [f"| the paper (V100) | - | {PAPER_TRAINING_H[1_500_000]} | "
              f"{PAPER_TRAINING_H[2_000_000]} |", "",
              f"Median of {len(t['intervals'])} intervals of "
              f"{t['log_every']} steps after {t['warmup_steps']} warm-up "
              f"steps (overall {t['steps_per_s_overall']:.3g} steps/s), "
              "`train.train_and_evaluate` with evaluation off, on "
              f"{t['dataset']['trajectories']} generated trajectories of "
              f"{t['dataset']['frames']} frames. Target, 1.5 M steps in "
              f"under {TARGET_TRAINING_H:g} h: "
              + ("not an accelerator" if cpu else _met(st["target_met"]))
              + ".", ""]
    t2 = t.get("second")
    if t2:
      rt2 = (rt or {}).get("second")
      lines += [f"### The {t2['config']} config (batch {t2['batch_size']}, "
                f"latent {t2['latent_size']}, "
                f"{t2['num_message_passing_steps']} steps)", "",
                f"| | steps/s | its {t2['own_num_steps']} steps (h) |",
                "|---|---|---|",
                f"| this device | {t2['steps_per_s']:.3g} | "
                f"{t2['own_projected_h']:.3g} |"]
      if rt2:
        lines.append(f"| CPU reference | {rt2['steps_per_s']:.3g} | "
                     f"{rt2['own_projected_h']:.3g} |")
      lines += ["", "Measured the same way, on "
                f"{t2['dataset']['trajectories']} generated trajectories of "
                "its own kind.", ""]
  return "\n".join(lines)
