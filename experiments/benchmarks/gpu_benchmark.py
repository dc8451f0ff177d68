"""Every accelerator figure in one command: MPM, GNS, training, agreement.

  python -m experiments.benchmarks --what=gpu --out=DIR \\
      [--gpu_parts=mpm,gns,train] [--cpu_reference=FILE]
  bash experiments/benchmarks/gpu.sh     # on an accelerator machine
                                         # (docs/performance.md)

One library call per part, :func:`run_part`, measures on this process's
first device and writes ``<stem>_<part>.json``; :func:`write_report`
assembles the parts found in the directory with the CPU reference into
``<stem>_benchmark.{json,md}`` (``run_benchmark`` does both). On an
accelerator the stem is ``gpu``; on the CPU it is ``gpu_cpu`` and the report
``gpu_cpu_reference.{json,md}``: the same programs at sizes one CPU core runs
in minutes (``gpu_sizes``), committed so that every accelerator figure has
this project's CPU figure beside it (``--cpu_reference``; the accelerator
machine's own CPU is another CPU). The parts, each in a module of its own
that says what it measures and how:

mpm (``gpu_mpm``): the paper scene (1000 particles, 600 frames) one at a
  time and B copies of it vmapped, the largest batch the device's memory
  allows, a batch of the paper dataset's scenes, the speed/accuracy study's
  spacings; and the agreement below.
gns (``gpu_gns``): the paper model rolling out the paper trajectory alone
  and batched (the paper's Table 2 measure), with its initial parameters
  and a still decoder; the shipped small model on its scene, and the
  agreement below.
train (``gpu_train``): steps per second of ``train.train_and_evaluate``
  with the paper config, projected to 1.5 M and 2 M steps beside the
  paper's 81.5 h and 134 h on a V100.

Agreement: the paper scene after ``AGREEMENT_EARLY_FRAME`` frames and after
599, and the small model's rollout after a few steps and at its end, on this
device against the same runs on a CPU: the accelerator machine's own CPU
(a child process with ``JAX_PLATFORMS=cpu``, same jax) and this project's
CPU reference (another jax, another CPU; its start window is used for the
learned rollout); ``gpu_agreement`` compares them, ``run_twin`` runs the
child. Tolerances (``gpu_report``'s constants) and why:

* early, per particle: at most ``EARLY_TOLERANCE_M`` = 1e-5 m (a tenth of a
  percent of a cell), before rounding differences have grown; a 1-ulp shift
  of the start moves particles by 4e-7 m there.
* final, the MPM: RMS over particles at most 1 mm, any particle at most 1 cm
  (one grid cell), and the 1% front and the centre of mass within 1 mm. A
  1-ulp shift of every start position on this CPU moves the final particles
  by 4e-5 m RMS and 2e-4 m at most (measured in the reference, the
  ``envelope``); an accelerator rounds differently in every one of 8,400
  substeps (scatter order, fused multiply-adds, its own log and sqrt), so
  tens of times that are rounding; a difference in the physics moves sand
  by cells.
* final, the learned rollout: the 1% front and the centre of mass within
  1 mm. Its particles are not compared at the end: the same 1-ulp shift of
  its start moves single particles by up to 1.4 cm (RMS 3 mm) after 194
  steps on this CPU, while its front and centre move by under 0.1 mm.
  The accelerator's default float32 matmul precision may be TF32; the
  rollout is also run at ``highest`` and both are reported.

Timing follows ``timing``'s rules: compilation apart (``compile_s``), a
warm-up call, ``jax.block_until_ready`` (or the library's own synchronised
clock), medians of repeats, calls compared with each other interleaved.
Where a CPU size runs fewer frames or steps than the trajectory, the
seconds per trajectory are extrapolated per substep or step and marked so.
"""

import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from typing import Any, Callable, Sequence

from absl import logging
import jax

from experiments import timing
from experiments.benchmarks import gpu_agreement
from experiments.benchmarks import gpu_gns
from experiments.benchmarks import gpu_mpm
from experiments.benchmarks import gpu_report
from experiments.benchmarks import gpu_sizes
from experiments.benchmarks import gpu_train
from experiments.benchmarks.gpu_sizes import Sizes
from mpm import io as mpm_io

PARTS = ("mpm", "gns", "train")
DEFAULT_REFERENCE = "docs/benchmarks/gpu_cpu_reference.json"


def stem_for(accelerator: bool) -> str:
  """``gpu`` on an accelerator, ``gpu_cpu`` on the CPU (the reference)."""
  return "gpu" if accelerator else "gpu_cpu"


def report_name(accelerator: bool) -> str:
  return "gpu_benchmark" if accelerator else "gpu_cpu_reference"


def load_reference(path: str | None) -> dict | None:
  """The CPU reference report (None: no path, or no such file)."""
  if not path or not os.path.exists(path):
    return None
  with open(path) as f:
    return json.load(f)


def is_accelerator() -> bool:
  return jax.default_backend() != "cpu"


def run_part(part: str, out_dir: str, *, quick: bool = False,
             reference: dict | None = None, command: str = "",
             accelerator: bool | None = None,
             log: Callable[[str], None] = logging.info) -> str:
  """Measures one part on this process's first device and writes
  ``<stem>_<part>[_quick].json`` to ``out_dir``; returns its path.

  ``accelerator`` (default: whether the first device is not a CPU) picks
  the role: sizes, file names, and the comparisons with a CPU twin
  process and ``reference`` (tests take the accelerator's path on the
  CPU). The file is rewritten after each measurement with what is
  measured so far and ``"complete": false``, and with ``true`` at the end:
  a part stopped by a time limit keeps its finished rows."""
  if part not in PARTS:
    raise ValueError(f"part {part!r}; allowed: {PARTS}")
  if accelerator is None:
    accelerator = is_accelerator()
  sizes = gpu_sizes.sizes_for(accelerator, quick)
  results: dict[str, Any] = {
      "part": part, "command": command,
      "environment": timing.environment(quick, device_kind=jax.devices()[0]
                                        .device_kind),
      "sizes": dataclasses.asdict(sizes), "complete": False}
  os.makedirs(out_dir, exist_ok=True)
  path = os.path.join(out_dir, f"{stem_for(accelerator)}_{part}"
                      + ("_quick" if quick else "") + ".json")

  def save(measured: dict[str, Any]) -> None:
    # What is measured so far, so that a part stopped by a time limit keeps
    # its finished rows (the report marks it partial).
    results[part] = measured
    timing.write_json(path, results)

  with tempfile.TemporaryDirectory() as work:
    twin = ((lambda kind: run_twin(kind, quick, work)) if accelerator
            else None)
    if part == "mpm":
      measured = gpu_mpm.measure_mpm(
          sizes, log, save, lambda out: gpu_mpm.mpm_agreement(
              out, sizes, twin, reference, envelope_here=not accelerator))
    elif part == "gns":
      measured = gpu_gns.measure_gns(sizes, log, save, twin, reference)
      if not accelerator:
        gpu_gns.gns_envelope_here(measured, sizes)
    else:
      measured = gpu_train.measure_training(sizes, log, work)
  timing.end_environment(results["environment"])
  results["complete"] = True
  save(measured)
  return path


def read_parts(out_dir: str, accelerator: bool,
               quick: bool) -> dict[str, dict]:
  """The part files of one role found in ``out_dir``."""
  parts = {}
  suffix = "_quick" if quick else ""
  for part in PARTS:
    path = os.path.join(out_dir,
                        f"{stem_for(accelerator)}_{part}{suffix}.json")
    if os.path.exists(path):
      with open(path) as f:
        parts[part] = json.load(f)
  return parts


def write_report(out_dir: str, accelerator: bool, *, quick: bool = False,
                 reference: dict | None = None,
                 reference_path: str | None = None) -> dict[str, Any]:
  """Assembles the parts in ``out_dir`` with the reference into
  ``<report_name>[_quick].{json,md}``; returns the report (with
  "markdown" and "files").

  Raises:
    FileNotFoundError: no part file of this role in ``out_dir``.
  """
  parts = read_parts(out_dir, accelerator, quick)
  if not parts:
    raise FileNotFoundError(
        f"{out_dir}: no {stem_for(accelerator)}_<part>"
        f"{'_quick' if quick else ''}.json to report on (parts: {PARTS})")
  # A part stopped before its first measurement has nothing to report.
  parts = {k: v for k, v in parts.items() if k in v}
  report = {"accelerator": accelerator, "reference_file": reference_path,
            # The reference's parts ran on one machine: its first part's.
            "reference_environment": next(iter(
                (reference or {}).get("environments", {}).values()), None),
            "parts": {k: v[k] for k, v in parts.items()},
            "complete": {k: v.get("complete", True)
                         for k, v in parts.items()},
            "environments": {k: v["environment"] for k, v in parts.items()},
            "commands": {k: v["command"] for k, v in parts.items()},
            "summary": gpu_report.summarise(parts, reference)}
  timing.write_results(out_dir, report_name(accelerator), quick, report,
                       gpu_report.to_markdown(report, reference))
  return report


def run_benchmark(out_dir: str, *, parts: Sequence[str] = PARTS,
                  quick: bool = False, cpu_reference: str | None = None,
                  command: str = "", accelerator: bool | None = None,
                  log: Callable[[str], None] = logging.info
                  ) -> dict[str, Any]:
  """Runs ``parts`` (each written as it ends), then the report.

  Args:
    out_dir: directory of the part files and the report (created).
    parts: subset of ``PARTS``; none: only the report, from the parts
      already in ``out_dir``.
    quick: tiny sizes (``gpu_sizes.QUICK``), seconds: a smoke test, not
      figures.
    cpu_reference: the CPU reference report (``DEFAULT_REFERENCE``); on the
      CPU itself it is not read (this run is one).
    command: the command line, recorded.
    accelerator: the role (default: whether the first device is not a
      CPU; see ``run_part``).
    log: called with one line per measurement.

  Returns:
    The report (its JSON's content, "markdown" and "files").
  """
  if accelerator is None:
    accelerator = is_accelerator()
  reference = load_reference(cpu_reference) if accelerator else None
  if accelerator and reference is None:
    log(f"no CPU reference ({cpu_reference}): figures without ratios")
  for part in parts:
    path = run_part(part, out_dir, quick=quick, reference=reference,
                    command=command, accelerator=accelerator, log=log)
    log(f"wrote {path}")
  return write_report(out_dir, accelerator, quick=quick,
                      reference=reference,
                      reference_path=cpu_reference if reference else None)


def report_all(out_dir: str, *, quick: bool = False,
               cpu_reference: str | None = DEFAULT_REFERENCE
               ) -> list[dict[str, Any]]:
  """Rebuilds the report of each role whose part files are in
  ``out_dir`` (``--gpu_parts=report``): the accelerator's with the CPU
  reference, the CPU reference's. Measures nothing, needs no device.

  Raises:
    FileNotFoundError: no part file of either role in ``out_dir``.
  """
  reports = []
  for accelerator in (True, False):
    if read_parts(out_dir, accelerator, quick):
      reference = load_reference(cpu_reference) if accelerator else None
      reports.append(write_report(
          out_dir, accelerator, quick=quick, reference=reference,
          reference_path=cpu_reference if reference else None))
  if not reports:
    raise FileNotFoundError(
        f"{out_dir}: no gpu_<part>{'_quick' if quick else ''}.json nor "
        f"gpu_cpu_<part>{'_quick' if quick else ''}.json to report on")
  return reports


# ------------------------------------------------------------ CPU twin ---


def twin_positions(kind: str, sizes: Sizes) -> dict[str, Any]:
  """What the CPU twin computes (on this process's device): for "mpm" the
  paper scene at the agreement frames, unperturbed and 1 ulp to the right;
  for "gns" the small model's start window and its rollout at the
  agreement steps, from it and from it 1 ulp to the right."""
  encode = gpu_agreement.encode_positions
  if kind == "mpm":
    scene = gpu_mpm.paper_scene(sizes.frames)
    frames = gpu_agreement.agreement_frames(sizes)
    return {"positions": encode(gpu_mpm.mpm_positions(scene, frames)),
            "perturbed": encode(gpu_mpm.mpm_positions(scene, frames,
                                                      perturb=True))}
  run, _, start, steps = gpu_gns.small_model_start(sizes.small_frames)
  at = gpu_gns.gns_agreement_steps(steps)
  return {"window": encode(start.window),
          "positions": encode(gpu_gns.small_rollout(run, start, steps)[at]),
          "perturbed": encode(gpu_gns.small_rollout(
              run, start, steps, gpu_agreement.one_ulp(start.window))[at])}


def run_twin(kind: str, quick: bool, workdir: str) -> dict[str, Any]:
  """``twin_positions`` in a child process on this machine's CPU
  (``JAX_PLATFORMS=cpu``, the same jax)."""
  path = os.path.join(workdir, f"twin_{kind}.json")
  env = {**os.environ, "JAX_PLATFORMS": "cpu"}
  subprocess.run([sys.executable, "-m", "experiments.benchmarks.gpu_benchmark",
                  "twin", kind, "quick" if quick else "full", path],
                 check=True, env=env)
  with open(path) as f:
    return json.load(f)


def _twin_main(argv: list[str]) -> None:
  """``python -m experiments.benchmarks.gpu_benchmark twin KIND SIZES
  PATH``: ``twin_positions`` written to PATH (JSON)."""
  _, kind, which, path = argv
  sizes = gpu_sizes.QUICK if which == "quick" else gpu_sizes.FULL
  mpm_io.write_text(path, json.dumps(twin_positions(kind, sizes)))


if __name__ == "__main__":
  _twin_main(sys.argv[1:])
