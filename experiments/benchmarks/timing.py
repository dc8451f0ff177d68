"""What the benchmarks share: the record of the machine, atomic writes."""

import datetime
import os
import platform
import tempfile
from typing import Any

import jax


def environment(quick: bool, **extra) -> dict[str, Any]:
  """Date, machine, software and load at the start of a benchmark."""
  return {
      "date": datetime.datetime.now(datetime.timezone.utc).isoformat(
          timespec="seconds"),
      "quick": quick,
      "python": platform.python_version(),
      "machine": platform.machine(), "platform": platform.platform(),
      "cpu_count": os.cpu_count(),
      "jax_version": jax.__version__,
      "jax_backend": jax.default_backend(),
      "jax_devices": [str(d) for d in jax.devices()],
      "xla_flags": os.environ.get("XLA_FLAGS", ""),
      "load_average_start": list(os.getloadavg()),
      **extra,
  }


def write_atomic(path: str, text: str) -> None:
  """Writes ``text`` to ``path`` through a temporary file and a rename."""
  directory = os.path.dirname(os.path.abspath(path))
  with tempfile.NamedTemporaryFile("w", dir=directory, delete=False,
                                   suffix=".tmp") as f:
    f.write(text)
    tmp = f.name
  os.chmod(tmp, 0o644)
  os.replace(tmp, path)
