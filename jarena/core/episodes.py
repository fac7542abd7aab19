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

EVAL_BASE = 0
VAL_BASE = 1 << 20
TRAIN_LOW = 1 << 30
TRAIN_HIGH = 1 << 31  # exclusive; the largest id is the largest int32

SPLITS = ("train", "val", "eval")

_ROOT_SEED = 0x5EED


def _fmix32(h: jax.Array) -> jax.Array:
    """MurmurHash3's 32-bit finaliser: a cheap bijective mix of a uint32."""
    h = h ^ (h >> 16)
    h = h * jnp.uint32(0x85EBCA6B)
    h = h ^ (h >> 13)
    h = h * jnp.uint32(0xC2B2AE35)
    return h ^ (h >> 16)


def sample_train_episode(key: jax.Array) -> jax.Array:
    """A training episode id, uniform in ``[TRAIN_LOW, TRAIN_HIGH)``, int32 scalar.

    Mixes the key's words with a cheap integer finaliser instead of a threefry hash (resets run every
    step under auto-reset): the episode's randomness itself still comes from threefry of its id.
    """
    if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.wrap_key_data(key)
    words = jax.random.key_data(key).astype(jnp.uint32)
    h = jnp.full(words.shape[:-1], 0x27D4EB2F, jnp.uint32)  # a seed apart from next_key's
    for i in range(words.shape[-1]):
        h = _fmix32(h ^ words[..., i])
    return ((h >> 2) | jnp.uint32(TRAIN_LOW)).astype(jnp.int32)


def next_key(key: jax.Array) -> jax.Array:
    """The key that seeds the episode after the one started from ``key`` (cheap: no threefry hash).

    A bijective integer mix of the key's words. It only chooses future training episode ids (see
    :func:`sample_train_episode`); each episode's own randomness is threefry of its id.
    """
    if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.wrap_key_data(key)
    words = jax.random.key_data(key).astype(jnp.uint32)
    mixed, carry = [], jnp.uint32(0x9E3779B9)
    for i in range(words.shape[-1]):
        carry = _fmix32(words[..., i] ^ carry)
        mixed.append(carry)
    return jax.random.wrap_key_data(jnp.stack(mixed, axis=-1), impl=jax.random.key_impl(key))


def split_episodes(split: str, num_val: int, num_eval: int) -> range:
    """The episode ids of ``split``: a fixed list for ``val`` and ``eval``, the sampling range for train."""
    if split == "eval":
        return range(EVAL_BASE, EVAL_BASE + num_eval)
    if split == "val":
        return range(VAL_BASE, VAL_BASE + num_val)
    if split == "train":
        return range(TRAIN_LOW, TRAIN_HIGH)
    raise ValueError(f"unknown split {split!r}; valid splits are {list(SPLITS)}")


def piece_key(episode: jax.Array, piece: int) -> jax.Array:
    """Key of one piece of an episode (0 dynamics, 1 task, 2 tool, 3 rng), a pure function of the id.

    ``fold_in(fold_in(root, piece), episode)``: one hash per piece, as the inner ``fold_in`` of
    constants is folded at compile time.
    """
    root = jax.random.fold_in(jax.random.key(_ROOT_SEED), piece)
    return jax.random.fold_in(root, jnp.asarray(episode, jnp.uint32))
