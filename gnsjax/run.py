"""A trained run as the library uses it: its problem, and loading it.

``Problem`` is what the data and the config fix for a model (statistics at
its frame stride, the noise folded in or not, domain, radius, graph spec,
node choice); it is stored with every checkpoint (``Problem.to_dict``), so
``load_run(workdir)`` restores a model for inference from the checkpoint
alone: no dataset, no optimiser.
"""

from collections.abc import Mapping
import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import ml_collections
import numpy as np

from gnsjax import checkpoint
from gnsjax import data
from gnsjax import features
from gnsjax import graph
from gnsjax import models
from gnsjax import simulator
from mpm import io as mpm_io


# Model settings added after models were shipped, with the value that
# reproduces a checkpoint written before them.
MODEL_DEFAULTS = {"smooth_cutoff": 0.0, "velocity_gate": False,
                  "solid_range": None}
# Model options that add a head a fine-tuning may add to its parent (its
# parameters start fresh, ``fine_tuning_params``); runs with and without
# one average (``gnsjax.averaging``).
ADDED_HEADS = ("velocity_gate",)


def model_config_dict(model_config) -> dict:
  """The model section as a dict, settings a checkpoint predates filled in."""
  return {**MODEL_DEFAULTS, **dict(model_config)}


# Settings besides the model's own that give its parameters their meaning:
# the data's (others, like trajectory counts, may change between a run and
# its fine-tuning) and the inputs'.
_PHYSICS = (("train", "input_frames"), ("train", "frame_stride"),
            ("dataset", "spacing"), ("dataset", "connectivity_radius"),
            ("dataset", "rheology"))
# Their values in configs that predate them.
_PHYSICS_DEFAULTS = {("dataset", "rheology"): "drucker_prager"}


def physics_differences(stored: dict, current: dict
                        ) -> list[tuple[str, Any, Any]]:
  """("section.key", stored value, current value) for each of those
  settings that differs between two config dicts."""
  value = lambda config, section, key: config.get(section, {}).get(
      key, _PHYSICS_DEFAULTS.get((section, key)))
  pairs = [(f"{section}.{key}", value(stored, section, key),
            value(current, section, key)) for section, key in _PHYSICS]
  return [(where, a, b) for where, a, b in pairs if a != b]


def create_model(model_config: ml_collections.ConfigDict
                 ) -> models.EncodeProcessDecode:
  model_config = model_config_dict(model_config)
  return models.EncodeProcessDecode(
      latent_size=model_config["latent_size"],
      hidden_layers=model_config["hidden_layers"],
      num_message_passing_steps=model_config["num_message_passing_steps"],
      type_embedding_size=model_config["type_embedding_size"],
      split_first_layer=model_config["split_first_layer"],
      smooth_cutoff=float(model_config["smooth_cutoff"]),
      velocity_gate=bool(model_config["velocity_gate"]),
      solid_range=model_config["solid_range"])


def fine_tuning_params(parent_params, fresh_params):
  """A fine-tuning's first parameters: the parent's, and where the new model
  has parameters the parent lacks (an added velocity gate), their fresh
  initial values. Shared parameters must have the same shapes."""
  if not isinstance(fresh_params, Mapping):
    if np.shape(parent_params) != np.shape(fresh_params):
      raise ValueError(f"parameter shapes differ: {np.shape(parent_params)} "
                       f"vs {np.shape(fresh_params)}")
    return parent_params
  missing = set(parent_params) - set(fresh_params)
  if missing:
    raise ValueError(f"the parent has parameters the model lacks: "
                     f"{sorted(missing)}")
  return {k: fine_tuning_params(parent_params[k], v) if k in parent_params
          else v for k, v in fresh_params.items()}


@dataclasses.dataclass(frozen=True)
class Problem:
  """What the data and the config fix for a model (host values).

  Attributes:
    stats: normalisation statistics per learned step, the training noise
      folded in if the run was trained so (what the model divides by).
    spec: the radius graph's static description: the connectivity radius
      R (m, ``radius``) and the domain (``bounds``) live there only.
    input_frames: C.
    frame_stride: k, stored frames per learned step.
    boundary_particles: whether boundary particles are graph nodes.
    sdf_spacing: node spacing of the scenes' SDF grids (m).
    noise_std: training noise, std of the last input velocity (m/step).
    folded_noise_std: the noise folded into ``stats`` (m/step; 0 if none):
      ``noise_std`` but in a fine-tuning that changed the noise.
  """
  stats: features.Stats
  spec: graph.GraphSpec
  input_frames: int = 6
  frame_stride: int = 1
  boundary_particles: bool = True
  sdf_spacing: float = 0.005
  noise_std: float = 0.0
  folded_noise_std: float = 0.0

  @property
  def radius(self) -> float:
    """Connectivity radius R (m)."""
    return self.spec.radius

  @property
  def bounds(self) -> np.ndarray:
    """float32 [2, 2] domain [[x_min, x_max], [y_min, y_max]] (m)."""
    return np.asarray(self.spec.bounds, np.float32)

  @property
  def context(self) -> simulator.Context:
    return simulator.Context(
        features.Stats(*(jnp.asarray(s) for s in self.stats)))

  def to_dict(self) -> dict:
    """JSON-able record, stored with every checkpoint (``from_dict``)."""
    return {**{k: np.asarray(v).tolist()
               for k, v in self.stats._asdict().items()},
            "bounds": np.asarray(self.bounds).tolist(), "radius": self.radius,
            "noise_std": self.noise_std,
            "folded_noise_std": self.folded_noise_std}


def _problem(config, stats: features.Stats, bounds, radius: float,
             noise_std: float, folded_noise_std: float) -> Problem:
  bounds = np.asarray(bounds, np.float32)
  spec = graph.GraphSpec(radius, tuple(map(tuple, bounds.tolist())),
                         config.train.capacity_multiplier)
  m = config.model
  return Problem(stats, spec, config.train.input_frames,
                 config.train.frame_stride, m.boundary_particles,
                 float(m.sdf_spacing or radius / 6), float(noise_std),
                 float(folded_noise_std))


def problem_from_dict(config, stored: dict) -> Problem:
  """The problem a checkpoint was trained on (``Problem.to_dict``)."""
  stats = features.Stats(*(np.asarray(stored[k], np.float32)
                           for k in features.Stats._fields))
  noise = float(stored["noise_std"])
  # Stored before fine-tunings could change the noise: the noise folded in
  # is the training noise.
  folded = float(stored.get("folded_noise_std",
                            noise if config.train.fold_noise else 0.0))
  return _problem(config, stats, stored["bounds"], float(stored["radius"]),
                  noise, folded)


def noise_std_of(train_config, stats: features.Stats) -> float:
  """The training noise (m/step): ``noise_velocity_fraction`` times the RMS
  velocity std of the data at the run's stride, or ``noise_std``."""
  fraction = train_config.noise_velocity_fraction
  if fraction:
    return float(fraction * np.sqrt(np.mean(np.square(stats.vel_std))))
  return float(train_config.noise_std)


def fine_tuning_problem(parent: "Run", config) -> Problem:
  """The problem a fine-tuning of ``parent`` trains on: the parent's
  statistics (its weights are fit to them) and the config's training noise,
  ``noise_velocity_fraction`` taken of the data's velocity std (the parent's
  own noise unfolded from it), or ``noise_std``."""
  stats = features.unfold_noise(parent.problem.stats,
                                parent.problem.folded_noise_std)
  return dataclasses.replace(parent.problem,
                             noise_std=noise_std_of(config.train, stats))


def load_problem(data_dir: str, config) -> Problem:
  """The problem of a dataset: statistics at the config's frame stride (the
  noise folded in if ``train.fold_noise``), domain and radius (the model
  config's radius, if set, wins)."""
  train_path = data.split_path(data_dir, "train")
  stats = data.load_stats(train_path, config.train.frame_stride)
  header = mpm_io.read_header(train_path)
  noise_std = noise_std_of(config.train, stats)
  if config.train.fold_noise:
    stats = features.fold_noise(stats, noise_std)
  radius = float(config.model.connectivity_radius or
                 header["connectivity_radius"])
  return _problem(config, stats, header["bounds"], radius, noise_std,
                  noise_std if config.train.fold_noise else 0.0)


class Run(NamedTuple):
  """A trained model, ready for inference (no optimiser).

  Attributes:
    model: the network; params: its parameters.
    problem: statistics, graph and feature settings it was trained with.
    step: the checkpoint's training step; config: the run's config.
  """
  model: models.EncodeProcessDecode
  params: Any
  problem: Problem
  step: int
  config: ml_collections.ConfigDict


def _open(workdir: str, step: int | None):
  """(manager, step): ``step`` or, when None, the latest checkpoint's."""
  mngr = checkpoint.manager(workdir, every_steps=1)
  step = mngr.latest_step() if step is None else step
  if step is None:
    mngr.close()
    raise FileNotFoundError(f"{workdir}: no checkpoint to restore")
  return mngr, step


def load_config(workdir: str, step: int | None = None
                ) -> ml_collections.ConfigDict:
  """The config a run's checkpoint (default: the latest) was trained with,
  read without restoring any array."""
  mngr, step = _open(workdir, step)
  try:
    return ml_collections.ConfigDict(checkpoint.read_config(mngr, step))
  finally:
    mngr.close()


def load_run(workdir: str, step: int | None = None) -> Run:
  """A run's checkpoint (default: the latest), restored on its own.

  Every checkpoint stores its config and its problem (statistics, domain,
  radius), so a work directory, or a shipped model such as
  ``experiments/pretrained/small``, needs no dataset to restore.
  """
  mngr, step = _open(workdir, step)
  try:
    config = ml_collections.ConfigDict(checkpoint.read_config(mngr, step))
    problem = problem_from_dict(config, checkpoint.read_stats(mngr, step))
    model = create_model(config.model)
    abstract = models.init_params(
        model, jax.random.key(0),
        features.num_node_features(config.train.input_frames))
    params = checkpoint.restore_params(mngr, abstract, step)
  finally:
    mngr.close()
  return Run(model, params, problem, int(step), config)
