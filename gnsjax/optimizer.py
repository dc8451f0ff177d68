"""The training optimiser: Adam on the GNS learning-rate schedule after
clipping the gradient's global norm, optionally on some modules only."""

import optax

from gnsjax import config as config_lib


def learning_rate_schedule(lr_init: float, lr_min: float, decay_steps: int):
  """GNS decay: lr_min + (lr_init - lr_min) 0.1^(step / decay_steps).

  (optax.exponential_decay's end_value clamps instead of adding a floor.)
  """
  def schedule(step):
    return lr_min + (lr_init - lr_min) * 0.1**(step / decay_steps)
  return schedule


def trainable_modules(train_config) -> tuple:
  """The top-level modules ``train.trainable`` names ('': all of them)."""
  names = train_config.trainable.split(",")
  return tuple(n.strip() for n in names if n.strip())


def create_optimizer(train_config) -> optax.GradientTransformation:
  """Adam on the GNS schedule after clipping the gradient's global norm.

  With ``train.trainable`` set, only those top-level modules learn (their
  gradient alone is clipped); the others keep their values and carry no
  optimiser state.
  """
  schedule = learning_rate_schedule(train_config.lr_init, train_config.lr_min,
                                    train_config.lr_decay_steps)
  tx = optax.chain(optax.clip_by_global_norm(train_config.clip_norm),
                   optax.adam(schedule))
  modules = trainable_modules(train_config)
  if not modules:
    return tx

  def labels(params):
    inner = params["params"]
    unknown = set(modules) - set(inner)
    if unknown:
      raise config_lib.InputError(
          f"config.train.trainable names {sorted(unknown)}; allowed: the "
          f"model's modules {sorted(inner)}, comma-separated, or '' for all")
    # A prefix of the parameters: one label per top-level module.
    return {"params": {k: "train" if k in modules else "frozen"
                       for k in inner}}
  return optax.multi_transform({"train": tx, "frozen": optax.set_to_zero()},
                               labels)
