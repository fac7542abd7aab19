"""The on-device buffer: a frozen bundle of pure ``init / add / sample / can_sample`` functions.

In the manner of flashbax, :func:`make_buffer` validates its arguments, binds them, and returns a
:class:`Buffer`; variants come from ``buffer.replace(sample=...)``, not subclasses. The caller jits::

    buffer = jarena.data.make_buffer(num_arenas=B, capacity=1_000_000, sample_batch_size=256,
                                     mode="window", length=8)
    state = buffer.init(jarena.data.experience_spec(arena))       # one item, no batch axes
    add = jax.jit(buffer.add, donate_argnums=0)                   # updates the buffer in place
    state = add(state, transition_from(info, action, next_info))  # leaves (B, ...): one step of B arenas
    batch = jax.jit(buffer.sample)(state, key)                    # BufferSample, leaves (256, 8, ...)

Layout: one ring per arena, stored time-major like rollouts: every leaf has shape
``(capacity_per_arena, num_arenas, *item_shape)``, so adding one step of B arenas writes one
contiguous block (``lax.dynamic_update_slice``, in place when the state is donated), and a rollout's
``(T, B, ...)`` arrays add in one call. Besides the items the state keeps, per slot (packed in one
int32, ``meta``), how far it is into a contiguous stretch of one episode (``run``, from the items'
episode ids and step indices), whether the episode ended there, and whether it ends an episode added
from its first step; so window and trajectory sampling (:mod:`jarena.data.sampling`) never cross an
episode boundary unless asked to.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.data import marks, sampling
from jarena.data.accessors import DEFAULT, Accessors, BufferError
from jarena.data.buffer_state import BufferState
from jarena.data.sampling import BufferSample

Array = jax.Array
PyTree = Any

MODES = ("transition", "window", "window_across", "trajectory")


@dataclasses.dataclass(frozen=True)
class Buffer:
    """A buffer: pure functions over :class:`BufferState`; jit them as the caller.

    Attributes:
      init: ``(item) -> state``; ``item`` is one transition (arrays or ``jax.ShapeDtypeStruct``).
      add: ``(state, batch) -> state``; ``batch`` leaves are (B, *item) for one step of the B arenas or
        (T, B, *item) for T steps. Donate the state (``jax.jit(add, donate_argnums=0)``) to update in place.
      sample: ``(state, key) -> BufferSample``.
      can_sample: ``(state) -> bool scalar``; enough items, and at least one valid unit to sample.
    """

    init: Callable[[PyTree], BufferState]
    add: Callable[[BufferState, PyTree], BufferState]
    sample: Callable[[BufferState, Array], BufferSample]
    can_sample: Callable[[BufferState], Array]

    def replace(self, **changes) -> Buffer:
        """A copy with some functions replaced, e.g. ``sample=partial(sample_windows, ...)``."""
        return dataclasses.replace(self, **changes)


def _path_name(path) -> str:
    return jax.tree_util.keystr(path) or "<item>"


# ---------------------------------------------------------------------------------------------- init / add
def init(item: PyTree, *, num_arenas: int, capacity_per_arena: int, accessors: Accessors = DEFAULT) -> BufferState:
    """An empty buffer state for items shaped like ``item`` (one transition, no batch axes)."""
    for what, fn, kinds in (("episode id", accessors.episode_of, "iu"), ("step", accessors.step_of, "iu"),
                            ("done flag", accessors.done_of, "b")):
        value = jax.eval_shape(fn, item)
        if value.shape != () or np.dtype(value.dtype).kind not in kinds:
            raise BufferError(f"init: the item's {what} must be a scalar of kind {kinds!r}, got shape "
                              f"{value.shape} and dtype {value.dtype}")
    c, b = capacity_per_arena, num_arenas
    experience = jax.tree_util.tree_map(lambda x: jnp.zeros((c, b) + tuple(x.shape), x.dtype), item)
    # Distinct arrays for every field: a donated state must not hold one buffer twice.
    return BufferState(experience=experience, meta=jnp.zeros((c, b), jnp.int32),
                       last_episode=jnp.full((b,), -1, jnp.int32), last_step=jnp.full((b,), -1, jnp.int32),
                       last_run=jnp.zeros((b,), jnp.int32), position=jnp.zeros((), jnp.int32),
                       count=jnp.zeros((), jnp.int32))


def _steps_in(state: BufferState, batch: PyTree) -> int | None:
    """Validates ``batch`` against the buffer statically; returns T for (T, B, ...) leaves, None for (B, ...)."""
    want_def = jax.tree_util.tree_structure(state.experience)
    got_def = jax.tree_util.tree_structure(batch)
    if want_def != got_def:
        raise BufferError(f"add: the batch's structure differs from the buffer's items.\n  buffer: {want_def}\n"
                          f"  batch:  {got_def}")
    c, b = state.meta.shape
    steps = set()
    for (path, stored), got in zip(jax.tree_util.tree_leaves_with_path(state.experience),
                                   jax.tree_util.tree_leaves(batch), strict=True):
        item_shape = stored.shape[2:]
        shape, dtype = tuple(np.shape(got)), jnp.result_type(got)
        if shape == (b,) + item_shape:
            steps.add(None)
        elif len(shape) == len(item_shape) + 2 and shape[1] == b and shape[2:] == item_shape:
            steps.add(shape[0])
        else:
            raise BufferError(f"add: leaf {_path_name(path)} has shape {shape}; expected ({b}, *{item_shape}) "
                              f"for one step of {b} arenas or (T, {b}, *{item_shape}) for T steps")
        if dtype != stored.dtype:
            raise BufferError(f"add: leaf {_path_name(path)} has dtype {dtype}; the buffer stores {stored.dtype}")
    if len(steps) > 1:
        raise BufferError(f"add: leaves disagree on the number of steps (leading axes {sorted(steps, key=str)})")
    (t,) = steps
    if t is not None and not 1 <= t <= c:
        raise BufferError(f"add: a batch of {t} steps per arena; the buffer holds 1 to {c} steps per arena")
    return t


def add(state: BufferState, batch: PyTree, *, accessors: Accessors = DEFAULT) -> BufferState:
    """Adds one step (leaves (B, ...)) or T steps (leaves (T, B, ...)) of B arenas, overwriting the oldest."""
    t = _steps_in(state, batch)
    if t is None:
        batch = jax.tree_util.tree_map(lambda x: jnp.expand_dims(x, 0), batch)
        t = 1
    c, b = state.meta.shape
    episode = jnp.asarray(accessors.episode_of(batch)).astype(jnp.int32)
    step = jnp.asarray(accessors.step_of(batch)).astype(jnp.int32)
    done = jnp.asarray(accessors.done_of(batch)).astype(bool)
    for what, x in (("episode ids", episode), ("steps", step), ("done flags", done)):
        if x.shape != (t, b):
            raise BufferError(f"add: the batch's {what} have shape {x.shape}, expected {(t, b)}")

    # Where each new item continues the stretch of its arena's previous item, and how far into it it is.
    prev_run = state.last_run
    if t == 1:
        continues = (episode[0] == state.last_episode) & (step[0] == state.last_step + 1) & (state.count > 0)
        run = jnp.where(continues, prev_run + 1, 1)[None]
    else:
        prev_episode = jnp.concatenate([state.last_episode[None], episode[:-1]])
        prev_step = jnp.concatenate([state.last_step[None], step[:-1]])
        continues = (episode == prev_episode) & (step == prev_step + 1)
        continues = continues.at[0].set(continues[0] & (state.count > 0))
        index = jnp.arange(t, dtype=jnp.int32)[:, None]
        last_break = jax.lax.cummax(jnp.where(continues, -1, index), axis=0)
        run = jnp.where(last_break >= 0, index - last_break + 1, prev_run[None] + index + 1)

    def write(stored, new):
        if t == 1:
            return jax.lax.dynamic_update_slice_in_dim(stored, new, state.position, axis=0)
        slots = (state.position + jnp.arange(t)) % c
        return stored.at[slots].set(new, unique_indices=True)

    meta = marks.pack(run, done, done & (step + 1 == run))
    return state.replace(experience=jax.tree_util.tree_map(write, state.experience, batch),
                         meta=write(state.meta, meta), last_episode=episode[-1], last_step=step[-1], last_run=run[-1],
                         position=(state.position + t) % c, count=jnp.minimum(state.count + t, c))


# ---------------------------------------------------------------------------------------------- factory
def _positive_int(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise BufferError(f"{name} must be a positive int, got {value!r}")
    return int(value)


def make_buffer(num_arenas: int, capacity: int, sample_batch_size: int, *, mode: str = "transition",
                length: int | None = None, min_size: int = 1, complete_only: bool = True,
                episode_of: Callable[[PyTree], Array] | None = None, step_of: Callable[[PyTree], Array] | None = None,
                done_of: Callable[[PyTree], Array] | None = None) -> Buffer:
    """Builds a :class:`Buffer` for batches from ``num_arenas`` arenas.

    Args:
      num_arenas: B, the arenas whose steps each ``add`` receives.
      capacity: items stored over all arenas (a multiple of B; each arena keeps ``capacity // B``).
      sample_batch_size: S, units per sample.
      mode: what ``sample`` draws (:mod:`jarena.data.sampling`): ``"transition"`` (leaves (S, ...)),
        ``"window"`` (``length`` consecutive items of one episode, (S, L, ...)), ``"window_across"``
        (``length`` consecutive items of one arena, crossing episodes, with ``first`` / ``done`` flags),
        ``"trajectory"`` (whole episodes padded to ``length`` items, with a mask).
      length: L for the window modes; the padded length for ``"trajectory"`` (longer episodes are cut).
      min_size: items (over all arenas) needed before ``can_sample`` is true.
      complete_only: ``"trajectory"`` mode samples only episodes stored from step 0 to their end;
        ``False`` also samples partly overwritten or unfinished ones.
      episode_of: reads an item's (or batch's) int episode id; by default ``.episode``. The defaults of
        these three read attributes or mapping keys, as in :class:`jarena.data.Experience`.
      step_of: reads an item's (or batch's) int step within its episode; by default ``.step``.
      done_of: reads an item's (or batch's) bool end-of-episode flag; by default ``.terminated | .truncated``.

    Raises:
      BufferError: naming the bad argument and the valid choices.
    """
    num_arenas = _positive_int("num_arenas", num_arenas)
    capacity = _positive_int("capacity", capacity)
    sample_batch_size = _positive_int("sample_batch_size", sample_batch_size)
    min_size = _positive_int("min_size", min_size)
    if capacity % num_arenas:
        raise BufferError(f"capacity={capacity} must be a multiple of num_arenas={num_arenas} (each arena keeps "
                          f"capacity // num_arenas items), e.g. {capacity - capacity % num_arenas or num_arenas}")
    per_arena = capacity // num_arenas
    if mode not in MODES:
        raise BufferError(f"unknown mode {mode!r}; valid modes are {list(MODES)}")
    if mode == "transition":
        if length is not None:
            raise BufferError("mode='transition' samples single items; length must be None")
    else:
        length = _positive_int(f"length (needed by mode={mode!r})", length)
        if length > per_arena:
            raise BufferError(f"length={length} exceeds the {per_arena} items each arena keeps "
                              f"(capacity {capacity} // num_arenas {num_arenas})")
    if min_size > capacity:
        raise BufferError(f"min_size={min_size} exceeds capacity={capacity}")
    accessors = Accessors(episode_of=episode_of or DEFAULT.episode_of, step_of=step_of or DEFAULT.step_of,
                          done_of=done_of or DEFAULT.done_of)

    if mode == "transition":
        sample = functools.partial(sampling.sample_transitions, batch_size=sample_batch_size, accessors=accessors)
        ready = sampling.can_sample_transitions
    elif mode == "trajectory":
        sample = functools.partial(sampling.sample_trajectories, batch_size=sample_batch_size, max_length=length,
                                   complete_only=complete_only, accessors=accessors)
        ready = functools.partial(sampling.can_sample_trajectories, complete_only=complete_only)
    else:
        across = mode == "window_across"
        sample = functools.partial(sampling.sample_windows, batch_size=sample_batch_size, length=length,
                                   across=across, accessors=accessors)
        ready = functools.partial(sampling.can_sample_windows, length=length, across=across)

    def can_sample(state: BufferState) -> Array:
        return (state.size >= min_size) & ready(state)

    return Buffer(init=functools.partial(init, num_arenas=num_arenas, capacity_per_arena=per_arena,
                                         accessors=accessors),
                  add=functools.partial(add, accessors=accessors), sample=sample, can_sample=can_sample)
