"""Trains the learned simulator (resumes a killed run from its checkpoint).

  python -m experiments.train --config=experiments/configs/small.py \
      --data=DATA_DIR --workdir=WORKDIR [--config.train.num_steps=...]
"""

from absl import flags
from absl import logging
import jax
from ml_collections import config_flags

from experiments import runtime
from gnsjax import train

_CONFIG = config_flags.DEFINE_config_file("config", None, "Config file.",
                                          lock_config=True)
_DATA = flags.DEFINE_string("data", None, "Dataset directory (train.h5, ...).")
_WORKDIR = flags.DEFINE_string("workdir", None, "Run directory.")


def main(argv):
  del argv
  try:
    train.check_config(_CONFIG.value)
  except ValueError as e:
    raise runtime.InputError(f"--config: {e}") from e
  runtime.existing_dir("data", _DATA.value, holding="train.h5")
  runtime.writable("workdir", _WORKDIR.value)
  runtime.enable_compilation_cache()
  logging.info("devices: %s", jax.devices())
  metrics = train.train_and_evaluate(_CONFIG.value, _DATA.value,
                                     _WORKDIR.value)
  for k, v in sorted(metrics.items()):
    print(f"{k}: {v:.6g}")


if __name__ == "__main__":
  flags.mark_flags_as_required(["config", "data", "workdir"])
  runtime.run(main)
