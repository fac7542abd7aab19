"""Offline PlaNet: the world model learns from a :class:`~jarena.data.TrajectoryDataset` alone, as PlaNet-ClothPick
does on cloth (Kadi & Terzić); no arena is stepped while training.

The dataset (config key ``dataset``, e.g. written by ``jarena collect``) is read whole onto the device, into the
train state (as ``bc`` keeps its demonstrations: checkpoints carry it and a resumed run continues bit for bit). Each
update is one model gradient step (a "step" of ``total_steps``, as for ``bc``) on ``batch_size`` windows of
``sequence_length`` transitions (:func:`jarena_agents.datasets.sample_windows`), each inside one trajectory and
drawn uniformly among all such windows, as the online window buffer draws them inside one episode: the window's
first observation starts the latent from the initial state, and the observations, actions, per-step rewards and
``terminated`` flags of its transitions follow (:func:`jarena_agents.world_model.model.sequences_from_dataset`). A
trajectory that ends by a time limit or by the collection stopping is not terminated: the continue head learns 1
there, as online.

``augment: rotate90`` turns each window by a random number of quarter turns (the same for all its steps), its
pick-and-place points with it (:func:`jarena_agents.augment.random_rotate90`), for top-down images of scenes with no
preferred direction (PlaNet-ClothPick turns and flips its cloth images).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.core.arena import Arena, ArenaSpec
from jarena.data.schema import DatasetError
from jarena_agents import augment
from jarena_agents.config import ConfigError
from jarena_agents.datasets import read_steps, sample_windows, to_device
from jarena_agents.world_model import model as wm
from jarena_agents.world_model import online

PyTree = Any
AUGMENTATIONS = ("none", "rotate90")


@struct.dataclass
class OfflineTrainState:
    """Everything an offline run needs to continue bit for bit: the model, its optimiser, the dataset as
    :func:`jarena_agents.datasets.read_steps` lays it out (on device), the RNG and the updates done."""

    params: PyTree
    opt_state: PyTree
    data: PyTree
    key: jax.Array
    update: jax.Array  # int32


def check_augment(augmentation: str, spec: ArenaSpec | None = None) -> None:
    """Raises a ``ConfigError`` for an unknown ``augment``, or (given the arena's ``spec``) for ``rotate90`` where
    the arena's samples cannot turn (:func:`jarena_agents.augment.check_rotate90`: square images and nothing else,
    Box actions in [-1, 1] with an even number of values)."""
    if augmentation not in AUGMENTATIONS:
        raise ConfigError(f"planet: unknown augment {augmentation!r}; choose from {list(AUGMENTATIONS)}")
    if augmentation == "rotate90" and spec is not None:
        augment.check_rotate90(spec, "planet")


def read_dataset(path: str, arena: Arena, sequence_length: int) -> dict[str, Any]:
    """The dataset at ``path`` (see :func:`jarena_agents.datasets.read_steps`); raises a ``DatasetError`` unless
    some trajectory holds a window of ``sequence_length`` transitions."""
    data = read_steps(path, arena, "planet")
    longest = int(data["lengths"].max())
    if longest < sequence_length:
        raise DatasetError(f"planet: sequence_length={sequence_length} needs trajectories of at least that many "
                           f"steps (windows stay inside one trajectory); the longest in {path!r} has {longest}: set "
                           f"sequence_length to at most {longest}")
    return data


def rotate_windows(key: jax.Array, batch: dict, images: tuple[str, ...]) -> dict:
    """``batch`` (windows (S, L, ...)) with each window's images and pick-and-place points turned by one random
    number of quarter turns."""
    frames = {}
    for group in ("observation", "next_observation"):
        for k in images:  # (S, L, H, W, C) as (S, H, W, L C): all steps of a window turn together
            x = batch[group][k]
            frames[(group, k)] = jnp.moveaxis(x, 1, 3).reshape(x.shape[:1] + x.shape[2:4] + (-1,))
    (name, action), = batch["action"].items()
    turned, points = augment.random_rotate90(key, {f"{g}/{k}": v for (g, k), v in frames.items()},
                                             action.reshape(action.shape[:2] + (-1, 2)))
    out = {**batch, "observation": dict(batch["observation"]), "next_observation": dict(batch["next_observation"]),
           "action": {name: points.reshape(action.shape).astype(action.dtype)}}
    for (group, k), x in frames.items():
        shape = batch[group][k].shape
        out[group][k] = jnp.moveaxis(turned[f"{group}/{k}"].reshape(x.shape[:3] + (shape[1], shape[-1])), 3, 1)
    return out


def init_training(cfg, model: wm.WorldModel, optimizer, key: jax.Array, arena: Arena) -> OfflineTrainState:
    """The model's initial params and optimiser state, and the dataset ``cfg.dataset`` read onto the device (read
    on the host when this is traced, handed over by a host callback: no compiled program embeds it)."""
    check_augment(cfg.augment, arena.spec)
    data = to_device(read_dataset(cfg.dataset, arena, cfg.sequence_length))
    key, model_key = jax.random.split(key)
    params = wm.init_params(model, model_key)
    return OfflineTrainState(params=params, opt_state=optimizer.init(params), data=data, key=key,
                             update=jnp.zeros((), jnp.int32))


def update(cfg, model: wm.WorldModel, optimizer, ts: OfflineTrainState) -> tuple[OfflineTrainState, dict]:
    """One model gradient step on a batch of windows: the train state and its metrics (the model's losses;
    ``episodes`` 0, since no episode runs while training)."""
    key, sample_key, turn_key, loss_key = jax.random.split(ts.key, 4)
    batch = sample_windows(ts.data, sample_key, cfg.batch_size, cfg.sequence_length)
    if cfg.augment == "rotate90":
        batch = rotate_windows(turn_key, batch, model.images)
    seq = wm.sequences_from_dataset(model.spec, batch)
    params, opt_state, metrics, _ = online.sequence_step(model, optimizer, ts.params, ts.opt_state, seq, loss_key)
    ts = ts.replace(params=params, opt_state=opt_state, key=key, update=ts.update + 1)
    # train_and_evaluate logs the training return as nan: no environment episodes finish offline
    return ts, dict(metrics, episodes=jnp.zeros((), jnp.int32), episode_return=jnp.zeros((), jnp.float32))
