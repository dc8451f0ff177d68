"""The in-training evaluation of runs, read from their TensorBoard events.

``experiments.train`` writes ``eval/one_step_loss``, ``eval/rollout_mse``
and ``eval/rollout_mse_constant_velocity`` every ``config.eval.every_steps``
to ``WORKDIR/tensorboard`` only; this prints them as a table, one row per
run and step, without TensorBoard itself (tensorboardX's event protos).

  python docs/results/eval_scalars.py WORKDIR...
"""
import glob
import os
import struct
import sys

from tensorboardX.proto import event_pb2

_HEADER = 12   # record length (uint64) and its CRC (uint32)
_FOOTER = 4    # the data's CRC (uint32)


def events(path: str):
  """Yields the ``Event`` protos of one TFRecord file of events."""
  with open(path, "rb") as f:
    data = f.read()
  at = 0
  while at + _HEADER <= len(data):
    (length,) = struct.unpack("<Q", data[at:at + 8])
    event = event_pb2.Event()
    event.ParseFromString(data[at + _HEADER:at + _HEADER + length])
    at += _HEADER + length + _FOOTER
    yield event


def eval_scalars(workdir: str) -> dict[int, dict[str, float]]:
  """step -> {tag: value} of the run's ``eval/`` scalars (a resumed run's
  later value of a step wins)."""
  out = {}
  for path in sorted(glob.glob(os.path.join(workdir, "tensorboard", "*"))):
    for event in events(path):
      for value in event.summary.value:
        if value.tag.startswith("eval/"):
          out.setdefault(event.step, {})[value.tag] = value.simple_value
  return out


def main(workdirs):
  tags = ("eval/one_step_loss", "eval/rollout_mse",
          "eval/rollout_mse_constant_velocity")
  print("| run | step | " + " | ".join(tags) + " |")
  print("|---|---:|" + "---:|" * len(tags))
  for workdir in workdirs:
    for step, values in sorted(eval_scalars(workdir).items()):
      cells = " | ".join(f"{values[t]:.4g}" if t in values else "-"
                         for t in tags)
      print(f"| {workdir} | {step} | {cells} |")


if __name__ == "__main__":
  main(sys.argv[1:])
