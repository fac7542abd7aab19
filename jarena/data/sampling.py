"""Sampling from a :class:`~jarena.data.buffer.BufferState`: pure functions; the caller jits.

Four units, each drawn uniformly (with replacement) among those stored:

- :func:`sample_transitions`: single items, leaves (S, ...).
- :func:`sample_windows`: L consecutive items of one episode, leaves (S, L, ...); with ``across=True``,
  L consecutive items of one arena that may span episodes, flagged by ``first`` and ``done``.
- :func:`sample_trajectories`: whole episodes, leaves (S, L_max, ...), padded with zeros and ``mask``.

Positions are *logical* per arena: 0 is the oldest stored item, ``count - 1`` the newest; slot
``(oldest + i) % C`` holds logical item i. Windows never wrap from the newest item to the oldest.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from jarena.data import marks
from jarena.data.accessors import DEFAULT, Accessors
from jarena.data.buffer_state import BufferState

Array = jax.Array
PyTree = Any


@struct.dataclass
class BufferSample:
    """A batch drawn from a buffer (shapes (S,) for transitions, (S, L) for windows and trajectories).

    Attributes:
      experience: the items, leaves (S, ...) or (S, L, ...); zeros in the padding of trajectories.
      mask: bool; the item is real: false in the padding of trajectories, and everywhere when the buffer
        has nothing to sample (``can_sample`` false), where the items are arbitrary.
      first: bool; the item is the first stored one of its episode (its episode's start, or the oldest
        item left of it).
      done: bool; the episode ended with this item (its terminal flag, read by the buffer's ``done_of``).
    """

    experience: PyTree
    mask: Array
    first: Array
    done: Array


def _sizes(state: BufferState) -> tuple[int, int]:
    return state.meta.shape


def _oldest(state: BufferState) -> Array:
    c, _ = _sizes(state)
    return (state.position - state.count) % c


def _logical(state: BufferState, slot: Array) -> Array:
    c, _ = _sizes(state)
    return (slot - _oldest(state)) % c


def _gather(state: BufferState, logical: Array, arena: Array, mask: Array, accessors: Accessors,
            pad: bool = False) -> BufferSample:
    """Gathers the items at logical positions ``logical`` (S,) or (S, L) of arenas ``arena`` (broadcasting);
    with ``pad``, zeros where ``mask`` is false."""
    c, _ = _sizes(state)
    slot = (_oldest(state) + logical) % c

    def take(x):
        value = x[slot, arena]
        if not pad:
            return value
        return jnp.where(mask.reshape(mask.shape + (1,) * (value.ndim - mask.ndim)), value, jnp.zeros((), x.dtype))

    experience = jax.tree_util.tree_map(take, state.experience)
    # An item is first if its stored stretch of an episode starts there: for the first item of each unit
    # from the buffer's bookkeeping; for the items after it from their own episode ids and steps (the same
    # test that ``add`` made), which spares a second gather over the whole window.
    head = (slot, arena) if logical.ndim == 1 else (slot[:, 0], jnp.broadcast_to(arena, slot.shape)[:, 0])
    head_logical = logical if logical.ndim == 1 else logical[:, 0]
    first = jnp.minimum(marks.run(state.meta[head]), head_logical + 1) == 1
    if logical.ndim == 2:
        episode, step = accessors.episode_of(experience), accessors.step_of(experience)
        continues = (episode[:, 1:] == episode[:, :-1]) & (step[:, 1:] == step[:, :-1] + 1)
        first = jnp.concatenate([first[:, None], ~continues], axis=1)
    done = jnp.asarray(accessors.done_of(experience)).astype(bool)
    return BufferSample(experience=experience, mask=mask, first=first & mask, done=done & mask)


def _choose(key: Array, valid: Array, num: int) -> tuple[Array, Array]:
    """Draws ``num`` flat indices uniformly among the true entries of ``valid`` (exact, integer arithmetic).

    Returns ``(index, any_valid)``; indices are clipped into range when nothing is valid.
    """
    flat = valid.reshape(-1)
    cumulative = jnp.cumsum(flat.astype(jnp.int32))
    total = cumulative[-1]
    r = jax.random.randint(key, (num,), 0, jnp.maximum(total, 1))
    index = jnp.searchsorted(cumulative, r, side="right")
    return jnp.minimum(index, flat.shape[0] - 1), total > 0


# ---------------------------------------------------------------------------------------------- transitions
def sample_transitions(state: BufferState, key: Array, batch_size: int, accessors: Accessors = DEFAULT
                       ) -> BufferSample:
    """``batch_size`` stored items drawn uniformly; leaves (S, ...)."""
    _, b = _sizes(state)
    key_arena, key_time = jax.random.split(key)
    arena = jax.random.randint(key_arena, (batch_size,), 0, b)
    logical = jax.random.randint(key_time, (batch_size,), 0, jnp.maximum(state.count, 1))
    return _gather(state, logical, arena, jnp.full((batch_size,), state.count > 0), accessors)


def can_sample_transitions(state: BufferState) -> Array:
    return state.count > 0


# ---------------------------------------------------------------------------------------------- windows
def valid_window_ends(state: BufferState, length: int) -> Array:
    """bool (C, B): slots that end a stored window of ``length`` items of one episode."""
    c, _ = _sizes(state)
    logical = _logical(state, jnp.arange(c))[:, None]
    return (logical < state.count) & (jnp.minimum(state.run, logical + 1) >= length)


def sample_windows(state: BufferState, key: Array, batch_size: int, length: int, across: bool = False,
                   max_rounds: int = 8, accessors: Accessors = DEFAULT) -> BufferSample:
    """``batch_size`` windows of ``length`` consecutive items; leaves (S, L, ...).

    Without ``across`` every window lies inside one episode, drawn uniformly among all such windows:
    candidates are drawn uniformly and redrawn where they cross a boundary (O(S) per round); after
    ``max_rounds`` rounds, any still invalid are drawn exactly among all valid ends (O(C * B)). With
    ``across`` windows are drawn uniformly among all runs of L stored items of one arena, and
    ``first`` / ``done`` mark where episodes start and end inside them.
    """
    c, b = _sizes(state)
    key_arena, key_start, key_retry = jax.random.split(key, 3)
    num_starts = jnp.maximum(state.count - length + 1, 1)
    arena = jax.random.randint(key_arena, (batch_size,), 0, b)
    start = jax.random.randint(key_start, (batch_size,), 0, num_starts)
    ready = state.count >= length

    if not across:
        def ends_ok(start, arena):
            return marks.run(state.meta[(_oldest(state) + start + length - 1) % c, arena]) >= length

        def redraw(carry):
            start, arena, ok, i = carry
            k_arena, k_start = jax.random.split(jax.random.fold_in(key_retry, i))
            start = jnp.where(ok, start, jax.random.randint(k_start, (batch_size,), 0, num_starts))
            arena = jnp.where(ok, arena, jax.random.randint(k_arena, (batch_size,), 0, b))
            return start, arena, ends_ok(start, arena), i + 1

        carry = (start, arena, ends_ok(start, arena), 0)
        start, arena, ok, _ = jax.lax.while_loop(lambda x: (~jnp.all(x[2])) & (x[3] < max_rounds) & ready,
                                                 redraw, carry)

        def exact(args):
            start, arena, ok = args
            index, any_valid = _choose(jax.random.fold_in(key_retry, max_rounds), valid_window_ends(state, length),
                                       batch_size)
            end_slot, end_arena = index // b, index % b
            exact_start = _logical(state, end_slot) - (length - 1)
            return (jnp.where(ok, start, exact_start), jnp.where(ok, arena, end_arena), ok | any_valid)

        start, arena, ok = jax.lax.cond(jnp.all(ok), lambda args: args, exact, (start, arena, ok))
        ready = ready & ok[:, None]

    return _gather(state, start[:, None] + jnp.arange(length), arena[:, None],
                   jnp.broadcast_to(ready, (batch_size, length)), accessors)


def can_sample_windows(state: BufferState, length: int, across: bool = False) -> Array:
    if across:
        return state.count >= length
    return jnp.any(valid_window_ends(state, length))


# ---------------------------------------------------------------------------------------------- trajectories
def trajectory_anchors(state: BufferState, complete_only: bool = True) -> Array:
    """bool (C, B): one slot per stored episode that can be drawn whole (complete ones only, by default).

    A complete episode is anchored at its last item (it ends the episode, and the episode's step 0 is
    still stored); otherwise every stored stretch of an episode is anchored at its first stored item.
    """
    c, _ = _sizes(state)
    logical = _logical(state, jnp.arange(c))[:, None]
    stored = logical < state.count
    if complete_only:
        return stored & state.ends & (state.run <= logical + 1)
    return stored & (jnp.minimum(state.run, logical + 1) == 1)


def sample_trajectories(state: BufferState, key: Array, batch_size: int, max_length: int,
                        complete_only: bool = True, accessors: Accessors = DEFAULT) -> BufferSample:
    """``batch_size`` episodes drawn uniformly among stored ones; leaves (S, L_max, ...), zero padded.

    ``mask`` marks each episode's items; episodes longer than ``max_length`` are cut to their first
    ``max_length`` items. ``complete_only`` draws only episodes stored from step 0 to their end.
    """
    c, b = _sizes(state)
    index, any_valid = _choose(key, trajectory_anchors(state, complete_only), batch_size)
    anchor, arena = index // b, index % b
    start_slot = (anchor - marks.run(state.meta[anchor, arena]) + 1) % c if complete_only else anchor
    offset = jnp.arange(max_length)
    slot = (start_slot[:, None] + offset) % c
    start_run = marks.run(state.meta[start_slot, arena])[:, None]
    logical = _logical(state, start_slot)[:, None] + offset
    mask = (marks.run(state.meta[slot, arena[:, None]]) == start_run + offset) & (logical < state.count) & any_valid
    return _gather(state, jnp.where(mask, logical, 0), arena[:, None], mask, accessors, pad=True)


def can_sample_trajectories(state: BufferState, complete_only: bool = True) -> Array:
    return jnp.any(trajectory_anchors(state, complete_only))
