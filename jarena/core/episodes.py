"""Episode ids and the reproducible train / val / eval splits.

Every episode is named by an int32 id; its randomness (initial physics, goal, tool state) is derived
from the id alone, so episode 17 is the same on every machine and at every batch size. Evaluation ids
are ``0 .. n_eval - 1``, validation ids start at ``VAL_BASE``, and training draws ids uniformly from
``[TRAIN_LOW, TRAIN_HIGH) = [2^30, 2^31)``, a range disjoint from both.

Keys are derived with ``fold_in`` (one hash each, computed only where used), not ``split``: resets run
on every step under auto-reset, so their PRNG work is kept to a minimum.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

EVAL_BASE = 0
VAL_BASE = 1 << 20
TRAIN_LOW = 1 << 30
TRAIN_HIGH = 1 << 31  # exclusive; the largest id is the largest int32

SPLITS = ("train", "val", "eval")

_ROOT_SEED = 0x5EED


def sample_train_episode(key: jax.Array) -> jax.Array:
    """A training episode id drawn uniformly from ``[TRAIN_LOW, TRAIN_HIGH)``, int32 scalar (one 32-bit draw)."""
    bits = jax.random.bits(key, (), jnp.uint32)
    return ((bits >> 2) | jnp.uint32(TRAIN_LOW)).astype(jnp.int32)


def episode_of_key(key: jax.Array) -> jax.Array:
    """The training episode id that a reset ``key`` starts (and that an auto-reset draws from ``state.rng``)."""
    return sample_train_episode(jax.random.fold_in(key, 0))


def split_episodes(split: str, num_val: int, num_eval: int) -> range:
    """The episode ids of ``split``: a fixed list for ``val`` and ``eval``, the sampling range for train."""
    if split == "eval":
        return range(EVAL_BASE, EVAL_BASE + num_eval)
    if split == "val":
        return range(VAL_BASE, VAL_BASE + num_val)
    if split == "train":
        return range(TRAIN_LOW, TRAIN_HIGH)
    raise ValueError(f"unknown split {split!r}; valid splits are {list(SPLITS)}")


def check_episode_ids(episodes, where: str = "episode") -> None:
    """Raises ``ValueError`` when concrete episode ids (an int or an int array) fall outside
    ``[0, TRAIN_HIGH)``, naming the valid ranges of the splits.

    Ids under ``jit`` or ``vmap`` (tracers) are unknown and not checked: a negative id there names a
    valid but unlisted episode (its bits are reinterpreted as uint32).
    """
    if episodes is None or isinstance(episodes, jax.core.Tracer):
        return
    ids = np.atleast_1d(np.asarray(episodes))
    if ids.size and (ids.min() < 0 or ids.max() >= TRAIN_HIGH):  # two reductions: no per-id temporaries
        bad = ids[(ids < 0) | (ids >= TRAIN_HIGH)]
        raise ValueError(f"{where}: invalid episode id(s) {bad[:5].tolist()}; valid ids are in [0, 2^31) (eval "
                         f"from {EVAL_BASE}, val from {VAL_BASE}, train in [{TRAIN_LOW}, {TRAIN_HIGH}); "
                         "see arena.episodes(split))")


def piece_key(episode: jax.Array, piece: int) -> jax.Array:
    """Key of one piece of an episode (0 dynamics, 1 task, 2 tool, 3 rng), a pure function of the id.

    ``fold_in(fold_in(root, piece), episode)``: one hash per piece, as the inner ``fold_in`` of
    constants is folded at compile time.
    """
    root = jax.random.fold_in(jax.random.key(_ROOT_SEED), piece)
    return jax.random.fold_in(root, jnp.asarray(episode, jnp.uint32))
