"""A training config's keys and the checks made before any work: every key
present and known, values in range, and a resumed or fine-tuned run
compatible with the checkpoint it starts from.

A config is an ``ml_collections.ConfigDict`` from ``experiments/configs``
(``paper.py``, ``small.py``, ``test.py``).
"""

import json
import math

from gnsjax import run as run_lib
from mpm import scene as mpm_scene

# A config or checkpoint the user gave is wrong: entry points report it in one
# line (experiments.runtime).
InputError = mpm_scene.InputError

# The keys a training config must have (experiments/configs/paper.py).
CONFIG_KEYS = {
    "model": ("latent_size", "hidden_layers", "num_message_passing_steps",
              "type_embedding_size", "split_first_layer",
              "connectivity_radius", "boundary_particles", "sdf_spacing",
              "smooth_cutoff", "velocity_gate", "solid_range"),
    "train": ("seed", "batch_size", "num_steps", "input_frames",
              "frame_stride", "noise_std", "noise_velocity_fraction",
              "fold_noise", "motion_weighting", "pushforward_steps",
              "pushforward_probability", "pushforward_constrained",
              "rest_pushforward_steps", "rest_pushforward_probability",
              "rest_pushforward_speed", "rest_pushforward_stay",
              "unroll_steps", "unroll_probability", "unroll_moving_only",
              "target_outside_solids",
              "clean_fraction", "clean_resting_only", "clean_weight",
              "clean_scale_min",
              "lr_init", "lr_min", "lr_decay_steps", "clip_norm", "node_bucket",
              "capacity_multiplier", "max_wall_time_s", "device_windows",
              "init_from", "trainable"),
    "checkpoint": ("every_steps", "named_steps", "keep"),
    "eval": ("every_steps", "num_windows", "rollout_steps", "num_rollouts"),
}
_OTHER_TOP_LEVEL = ("dataset", "workers", "log_every")


def check_config(config) -> None:
  """Raises InputError (a ValueError) naming any unknown or missing key, or
  a value out of its range (``RANGES``)."""
  top = set(config.keys())
  allowed = set(CONFIG_KEYS) | set(_OTHER_TOP_LEVEL)
  if top - allowed:
    raise InputError(f"config: unknown key(s) {sorted(top - allowed)}; "
                     f"allowed: {sorted(allowed)}")
  for section, keys in CONFIG_KEYS.items():
    if section not in top:
      raise InputError(f"config: missing section '{section}' with keys "
                       f"{list(keys)}")
    present = set(config[section].keys())
    if present - set(keys):
      raise InputError(f"config.{section}: unknown key(s) "
                       f"{sorted(present - set(keys))}; allowed: {list(keys)}")
    if set(keys) - present:
      raise InputError(f"config.{section}: missing key(s) "
                       f"{sorted(set(keys) - present)}")
  for (section, key), (kind, lower, upper) in RANGES.items():
    value = config[section][key]
    if value is None and (section, key) in OPTIONAL:
      continue
    _check_value(f"config.{section}.{key}", value, kind, lower, upper)
  if config.train.lr_min > config.train.lr_init:
    raise InputError(f"config.train.lr_min = {config.train.lr_min} is above "
                     f"config.train.lr_init = {config.train.lr_init}; "
                     "allowed: lr_min <= lr_init")


# (section, key) -> (int or float, lower bound, upper bound); None: open.
RANGES = {
    ("model", "latent_size"): (int, 1, None),
    ("model", "hidden_layers"): (int, 1, None),
    ("model", "num_message_passing_steps"): (int, 1, None),
    ("model", "type_embedding_size"): (int, 1, None),
    ("model", "smooth_cutoff"): (float, 0.0, 1.0),
    ("model", "solid_range"): (float, 1e-12, None),
    ("train", "seed"): (int, 0, None),
    ("train", "batch_size"): (int, 1, None),
    ("train", "num_steps"): (int, 1, None),
    ("train", "input_frames"): (int, 2, None),
    ("train", "frame_stride"): (int, 1, None),
    ("train", "noise_std"): (float, 0.0, None),
    ("train", "noise_velocity_fraction"): (float, 0.0, None),
    ("train", "motion_weighting"): (float, 0.0, 1.0),
    ("train", "clean_fraction"): (float, 0.0, 1.0),
    ("train", "clean_weight"): (float, 0.0, None),
    ("train", "clean_scale_min"): (float, 0.0, 1.0),
    ("train", "pushforward_steps"): (int, 0, None),
    ("train", "pushforward_probability"): (float, 0.0, 1.0),
    ("train", "rest_pushforward_steps"): (int, 0, None),
    ("train", "rest_pushforward_probability"): (float, 0.0, 1.0),
    ("train", "rest_pushforward_speed"): (float, 0.0, None),
    ("train", "unroll_steps"): (int, 0, None),
    ("train", "unroll_probability"): (float, 0.0, 1.0),
    ("train", "max_wall_time_s"): (float, 0.0, None),
    ("train", "lr_init"): (float, 0.0, None),
    ("train", "lr_min"): (float, 0.0, None),
    ("train", "lr_decay_steps"): (float, 1e-12, None),
    ("train", "clip_norm"): (float, 1e-12, None),
    ("train", "node_bucket"): (int, 1, None),
    ("train", "capacity_multiplier"): (float, 1.0, None),
    ("checkpoint", "every_steps"): (int, 1, None),
    ("checkpoint", "keep"): (int, 1, None),
    ("eval", "every_steps"): (int, 0, None),
    ("eval", "num_windows"): (int, 1, None),
    ("eval", "rollout_steps"): (int, 1, None),
    ("eval", "num_rollouts"): (int, 0, None),
}
# Keys of ``RANGES`` whose None stands for a default.
OPTIONAL = {("model", "solid_range")}


def _check_value(where: str, value, kind: type, lower, upper) -> None:
  """InputError naming ``where`` unless ``value`` is a finite ``kind`` in
  [lower, upper] (an integral float passes as an int)."""
  number = (isinstance(value, (int, float)) and not isinstance(value, bool))
  if not number or not math.isfinite(value):
    raise InputError(f"{where} = {value!r}; allowed: a finite "
                     f"{'integer' if kind is int else 'number'}")
  if kind is int and int(value) != value:
    raise InputError(f"{where} = {value!r}; allowed: an integer")
  if ((lower is not None and value < lower) or
      (upper is not None and value > upper)):
    shown = {(0.0, None): ">= 0", (1e-12, None): "> 0"}.get(
        (lower, upper), f">= {lower:g}" if upper is None else
        f"{lower:g} to {upper:g}")
    raise InputError(f"{where} = {value!r}; allowed: {shown}")


def config_dict(config) -> dict:
  """The config as plain JSON values (what a checkpoint stores)."""
  return json.loads(config.to_json_best_effort())


def check_compatible(stored: dict, config) -> None:
  """Refuses to resume a run whose model or data physics differ."""
  current = config_dict(config)
  pairs = [("model", run_lib.model_config_dict(stored.get("model", {})),
            run_lib.model_config_dict(current.get("model", {})))]
  pairs += run_lib.physics_differences(stored, current)
  for where, old, new in pairs:
    if old != new:
      raise InputError(
          f"the checkpoint was trained with another config: its '{where}' is "
          f"{old}, this config has {new}; use a new --workdir or the same "
          "config")


def check_fine_tuning(stored: dict, config) -> None:
  """Refuses to start from a checkpoint of another architecture or physics.

  The model may differ in ``smooth_cutoff`` (it adds no parameter) and may
  add a velocity gate (whose parameters start fresh); the data and the
  inputs (``train.input_frames``, ``frame_stride``) must be the same.
  """
  old = run_lib.model_config_dict(stored.get("model", {}))
  new = run_lib.model_config_dict(config_dict(config)["model"])
  old["smooth_cutoff"] = new["smooth_cutoff"]
  for head in run_lib.ADDED_HEADS:
    old[head] = old[head] or new[head]
  compatible = dict(stored, model=old)
  try:
    check_compatible(compatible, config)
  except InputError as e:
    raise InputError(f"config.train.init_from = {config.train.init_from!r}: "
                     f"{e}") from None
