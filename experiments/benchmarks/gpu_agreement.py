"""Agreement of this device's positions with a CPU's, for the GPU command.

Positions written to JSON and read back, where the sand of a frame is (the
1% front and the centre of mass), the differences of two frames, a start
shifted by one float32 ulp (the envelope of rounding), and ``compare``,
which holds two runs (early and final frames) to the tolerances: their
values are ``gpu_report``'s constants, the reasons for them are in
``gpu_benchmark``'s module docstring. The parts compare their own runs with
these (``gpu_mpm.mpm_agreement``, ``gpu_gns.measure_small_model``).
"""

import base64
from typing import Any

import numpy as np

from experiments.benchmarks.gpu_report import AGREEMENT_EARLY_FRAME
from experiments.benchmarks.gpu_report import EARLY_TOLERANCE_M
from experiments.benchmarks.gpu_report import FINAL_MAX_TOLERANCE_M
from experiments.benchmarks.gpu_report import FINAL_MEASURE_TOLERANCE_M
from experiments.benchmarks.gpu_report import FINAL_RMS_TOLERANCE_M
from experiments.benchmarks.gpu_sizes import Sizes
from gnsjax import metrics

MEASURES = ("front_1pct_m", "centre_x_m", "centre_y_m")


def encode_positions(x: np.ndarray) -> dict[str, Any]:
  """float32 positions as JSON: shape and base64 of the bytes."""
  x = np.ascontiguousarray(x, np.float32)
  return {"shape": list(x.shape),
          "float32_base64": base64.b64encode(x.tobytes()).decode("ascii")}


def decode_positions(d: dict[str, Any]) -> np.ndarray:
  return np.frombuffer(base64.b64decode(d["float32_base64"]),
                       np.float32).reshape(d["shape"])


def measures(x: np.ndarray) -> dict[str, float]:
  """Where the sand of one frame [N, 2] (m) is: the 1% front (it flows
  toward smaller x, ``metrics.runout``) and the centre of mass."""
  x = np.asarray(x, np.float64)
  return {"front_1pct_m": float(metrics.runout(x)),
          "centre_x_m": float(np.mean(x[:, 0])),
          "centre_y_m": float(np.mean(x[:, 1]))}


def difference(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
  """Per-particle distances of two frames [N, 2] (m) and the measures'."""
  d = np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64),
                     axis=-1)
  ma, mb = measures(a), measures(b)
  return {"max_m": float(d.max()), "rms_m": float(np.sqrt(np.mean(d**2))),
          "median_m": float(np.median(d)),
          **{k: abs(ma[k] - mb[k]) for k in MEASURES}}


def one_ulp(window: np.ndarray) -> np.ndarray:
  """Positions [..., 2] with every x moved up by one float32 ulp."""
  w = np.array(window, np.float32)
  w[..., 0] = np.nextafter(w[..., 0], np.float32(np.inf))
  return w


def compare(x: np.ndarray, ref: np.ndarray, kind: str) -> dict[str, Any]:
  """This device's positions [2, N, 2] (early, final) against a CPU's.

  Returns:
    The differences at each, and whether each tolerance holds (the
    per-particle final ones only for the MPM, see ``gpu_benchmark``'s
    module docstring).
  """
  early, final = difference(x[0], ref[0]), difference(x[-1], ref[-1])
  checks = {"early_max": early["max_m"] <= EARLY_TOLERANCE_M,
            **{f"final_{k}": final[k] <= FINAL_MEASURE_TOLERANCE_M
               for k in MEASURES}}
  if kind == "mpm":
    checks["final_rms"] = final["rms_m"] <= FINAL_RMS_TOLERANCE_M
    checks["final_max"] = final["max_m"] <= FINAL_MAX_TOLERANCE_M
  return {"early": early, "final": final, "checks": checks,
          "agrees": all(checks.values())}


def agreement_frames(sizes: Sizes) -> list[int]:
  return [min(AGREEMENT_EARLY_FRAME, sizes.frames - 1), sizes.frames - 1]


def reference_part(reference: dict | None, part: str) -> dict | None:
  """One part of the CPU reference report (None: no reference, or not
  that part)."""
  if not reference:
    return None
  return reference.get("parts", {}).get(part)
