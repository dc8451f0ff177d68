"""Where a compiled XLA program spends its time, by kind of operation.

Used by the GNS benchmark (``gns_benchmark``, item 5: ``--what=gns``).

``breakdown(compiled, call)`` runs ``call`` (which executes ``compiled``)
under ``jax.profiler``, reads back the per-operation events of the trace and
sums their durations by what each operation of the optimised HLO does:

* ``dense``: dots (matmuls), alone or fused with their bias and activation;
* ``scatter``: scatters (``segment_sum`` and the transpose of gathers);
* ``gather``: gathers, alone or fused into elementwise work;
* ``reduce``: reductions (LayerNorm statistics, bias gradients, sums);
* ``elementwise``: the other fusions and copies.

A fusion is classed by the first of these kinds it contains. The trace format
is the profiler's, not a stable API: when it yields no operation events the
result says so (``skipped``) instead of failing.
"""

import collections
import glob
import gzip
import json
import os
import re
import tempfile
from typing import Any, Callable

import jax

KINDS = ("dense", "scatter", "gather", "reduce", "elementwise")
_COMPUTATION = re.compile(r"^(?:ENTRY\s+)?%?([\w.\-]+)\s.*\{\s*$")
_INSTRUCTION = re.compile(r"^\s*(?:ROOT\s+)?%([\w.\-]+)\s*=\s*(.*)$")
_OPCODE = re.compile(r"(?:^|[\s)}\]])([a-z][a-z0-9_\-]*)\(")
_CALLS = re.compile(r"(?:calls|to_apply)=%([\w.\-]+)")


def _parse_hlo(text: str):
  """{computation: [(name, opcode, called computations)]} of HLO text."""
  computations: dict[str, list] = {}
  current = None
  for line in text.splitlines():
    inst = _INSTRUCTION.match(line)
    if inst and current is not None:
      name, rest = inst.groups()
      op = _OPCODE.search(rest)
      computations[current].append(
          (name, op.group(1) if op else "", _CALLS.findall(rest)))
      continue
    comp = _COMPUTATION.match(line)
    if comp and "=" not in line.split("{")[0]:
      current = comp.group(1)
      computations[current] = []
  return computations


def classify(text: str) -> dict[str, str]:
  """Kind (one of ``KINDS``) of each instruction of an HLO module's text."""
  computations = _parse_hlo(text)
  memo: dict[str, set] = {}

  def contents(comp: str) -> set:
    if comp not in memo:
      memo[comp] = set()
      found = set()
      for _, op, calls in computations.get(comp, ()):
        found.add(op)
        for c in calls:
          found |= contents(c)
      memo[comp] = found
    return memo[comp]

  kinds = {}
  for comp in computations:
    for name, op, calls in computations[comp]:
      ops = {op}
      for c in calls:
        ops |= contents(c)
      if ops & {"dot", "convolution"}:
        kinds[name] = "dense"
      elif "scatter" in ops:
        kinds[name] = "scatter"
      elif "gather" in ops:
        kinds[name] = "gather"
      elif ops & {"reduce", "reduce-window"}:
        kinds[name] = "reduce"
      else:
        kinds[name] = "elementwise"
  return kinds


def breakdown(compiled, call: Callable[[], Any], repeats: int = 2
              ) -> dict[str, Any]:
  """Seconds per call by kind of operation, from a profiler trace.

  Args:
    compiled: the ``jax.stages.Compiled`` program that ``call`` runs.
    call: zero-argument function running it once (already warmed up).
    repeats: calls traced; durations are averaged over them.

  Returns:
    {"seconds": {kind: s per call}, "share": {kind: fraction}, "total_s",
    "top": [(instruction, kind, s per call)] of the ten slowest}, or
    {"skipped": reason}.
  """
  kinds = classify(compiled.as_text())
  with tempfile.TemporaryDirectory() as tmp:
    jax.block_until_ready(call())
    jax.profiler.start_trace(tmp)
    try:
      for _ in range(repeats):
        jax.block_until_ready(call())
    finally:
      jax.profiler.stop_trace()
    files = glob.glob(os.path.join(tmp, "**", "*.trace.json.gz"),
                      recursive=True)
    if not files:
      return {"skipped": "the profiler wrote no trace.json.gz"}
    with gzip.open(files[0]) as f:
      events = json.load(f).get("traceEvents", [])
  per_op = collections.Counter()
  for ev in events:
    if ev.get("ph") == "X" and ev.get("name") in kinds:
      per_op[ev["name"]] += ev.get("dur", 0) * 1e-6 / repeats
  if not per_op:
    return {"skipped": "no per-operation events in the trace"}
  seconds = {k: 0.0 for k in KINDS}
  for name, s in per_op.items():
    seconds[kinds[name]] += s
  total = sum(seconds.values())
  return {"seconds": seconds, "total_s": total,
          "share": {k: v / total for k, v in seconds.items()},
          "top": [(name, kinds[name], s)
                  for name, s in per_op.most_common(10)]}
