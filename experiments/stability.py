"""Where each simulator stays finite and physical, and where it breaks.

  python -m experiments.stability --out=docs/results/stability \
      [--workdir=experiments/pretrained/small] [--only=NAME,...]

The cases and checks are in ``experiments.extremes``; this writes their
table (``stability.csv``, ``stability.md``) and one picture per case.
"""

import os

from absl import flags
from absl import logging
import tqdm

import mpm
from experiments import evaluation
from experiments import extremes
from experiments import runtime
from gnsjax import train
from mpm import io as mpm_io

_OUT = flags.DEFINE_string("out", None, "Output directory for the table.")
_WORKDIR = flags.DEFINE_string(
    "workdir", "experiments/pretrained/small",
    "Trained run for the learned simulator's cases ('' to skip them).")
_ONLY = flags.DEFINE_list("only", None, "Run only these cases (names).")


def main(argv):
  del argv
  logging.set_verbosity(logging.WARNING)  # orbax's restore chatter
  runtime.writable("out", _OUT.value)
  cases = extremes.mpm_cases()
  run = None
  known = [c.name for c in cases]
  if _WORKDIR.value:
    runtime.existing_dir("workdir", _WORKDIR.value, holding="checkpoints")
    known += [c.name for c in extremes.gns_cases(0.01)]
  unknown = sorted(set(_ONLY.value or ()) - set(known))
  if unknown:
    raise mpm.InputError(f"--only: unknown case(s) {unknown}; allowed: "
                         f"{known}")
  runtime.enable_compilation_cache()
  if _WORKDIR.value:
    run = train.load_run(_WORKDIR.value)
    cases += extremes.gns_cases(run.config.dataset.spacing)
  if _ONLY.value:
    cases = [c for c in cases if c.name in _ONLY.value]
  os.makedirs(_OUT.value, exist_ok=True)
  rows = []
  for case in tqdm.tqdm(cases, unit="case"):
    outcome = (extremes.run_mpm(case) if case.simulator == "mpm" else
               extremes.run_gns(case, run))
    extremes.picture(outcome, os.path.join(_OUT.value, f"{case.name}.png"))
    rows.append(outcome.row)
    evaluation.write_csv(os.path.join(_OUT.value, "stability.csv"), rows)
  mpm_io.write_text(os.path.join(_OUT.value, "stability.md"),
                    extremes.table(rows))
  broken = [r["case"] for r in rows if r["status"] != "ok"]
  print(f"{len(rows)} cases, {len(broken)} not ok: {broken}; table: "
        f"{_OUT.value}/stability.md")


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
