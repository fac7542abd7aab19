"""``Loader``: batches from a :class:`~jarena.data.dataset.TrajectoryDataset`, in memory or streamed.

The draw is a pure function of the key: a jitted index function picks (trajectory, step) pairs
uniformly among the units of the chosen mode. When the selected trajectories fit in
``memory_budget`` bytes they are loaded onto the device once and batches are gathered there;
otherwise each batch streams from disk what it needs (raw fields: just its rows, from the chunk
files; compressed fields: the zarr chunks it touches, through an LRU cache within the budget), with
the next batches read ahead on a background thread. Both give the same batch for the same key.

Batches are dicts; leaves have a leading (S,) for transitions and (S, L) for windows and trajectories:
``observation``, ``next_observation``, ``action``, ``goal`` (dicts by output key, goal repeated per
step), ``reward``, ``terminated``, ``truncated``, ``mask`` (false in trajectory padding, where values
are zero), ``first`` / ``last`` (the step starts / ends its trajectory), ``trajectory`` (dataset index)
and ``step`` (index within the trajectory).
"""

from __future__ import annotations

import collections
import concurrent.futures
import functools
import itertools
import threading
from collections.abc import Iterator, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena.data.chunks import is_raw, read_row_set, read_rows
from jarena.data.schema import GROUPS, ROWS_PER, STEP_FIELDS, DatasetError

MODES = ("transition", "window", "window_across", "trajectory")
DEFAULT_BUDGET = 2 << 30


def _default_budget() -> int:
    """Half the default device's memory when it reports it, else 2 GiB."""
    stats = jax.devices()[0].memory_stats() or {}
    limit = stats.get("bytes_limit")
    return int(limit // 2) if limit else DEFAULT_BUDGET


@functools.partial(jax.jit, static_argnames=("mode", "batch_size", "length"))
def draw_indices(key: jax.Array, lengths: jax.Array, mode: str, batch_size: int, length: int
                 ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Draws ``batch_size`` units; returns ``(rank, step, mask)``, int32 / int32 / bool (S, L).

    ``rank`` indexes ``lengths`` (the selected trajectories' numbers of steps), ``step`` is the step within
    that trajectory (0 where ``mask`` is false).
    """
    lengths = lengths.astype(jnp.int32)
    offsets = jnp.arange(length, dtype=jnp.int32)

    def pick(weights):
        cumulative = jnp.cumsum(weights)
        r = jax.random.randint(key, (batch_size,), 0, jnp.maximum(cumulative[-1], 1))
        rank = jnp.searchsorted(cumulative, r, side="right").astype(jnp.int32)
        return rank, r - (cumulative[rank] - weights[rank])

    if mode in ("transition", "window"):
        rank, start = pick(jnp.maximum(lengths - length + 1, 0))
        rank, step = jnp.broadcast_to(rank[:, None], (batch_size, length)), start[:, None] + offsets
        mask = jnp.ones((batch_size, length), bool)
    elif mode == "window_across":
        cumulative = jnp.cumsum(lengths)
        start = jax.random.randint(key, (batch_size,), 0, jnp.maximum(cumulative[-1] - length + 1, 1))
        position = start[:, None] + offsets
        rank = jnp.searchsorted(cumulative, position, side="right").astype(jnp.int32)
        step = position - (cumulative[rank] - lengths[rank])
        mask = jnp.ones((batch_size, length), bool)
    else:
        rank = jax.random.randint(key, (batch_size,), 0, lengths.shape[0])
        mask = offsets < lengths[rank][:, None]
        rank, step = jnp.broadcast_to(rank[:, None], (batch_size, length)), jnp.where(mask, offsets, 0)
    return rank, step, mask


class _ChunkCache:
    """Whole zarr chunks read on demand, kept in LRU order within ``budget`` bytes; thread-safe."""

    def __init__(self, budget: int, workers: int = 8):
        self.budget, self.used, self.workers = max(int(budget), 0), 0, workers
        self.chunks: collections.OrderedDict = collections.OrderedDict()
        self.lock = threading.Lock()

    def _read(self, array, size: int, ids: list[int]) -> list[np.ndarray]:
        def read(c):
            return read_rows(array, c * size, min((c + 1) * size, array.shape[0]))

        if len(ids) < 2:
            return [read(c) for c in ids]
        with concurrent.futures.ThreadPoolExecutor(min(self.workers, len(ids))) as pool:
            return list(pool.map(read, ids))

    def rows(self, array, rows: np.ndarray, block: int = 64) -> np.ndarray:
        """``array[rows]``, reading each chunk it needs once (``block`` chunks at a time, to bound memory)."""
        size = array.chunks[0]
        out = np.empty((rows.shape[0],) + array.shape[1:], array.dtype)
        chunk_of = rows // size
        order = np.argsort(chunk_of, kind="stable")
        ids, firsts = np.unique(chunk_of[order], return_index=True)
        lasts = np.append(firsts[1:], rows.shape[0])
        for b in range(0, ids.size, block):
            with self.lock:
                missing = [int(c) for c in ids[b:b + block] if (id(array), int(c)) not in self.chunks]
            loaded = dict(zip(missing, self._read(array, size, missing), strict=True))
            with self.lock:
                for k in range(b, min(b + block, ids.size)):
                    c, key = int(ids[k]), (id(array), int(ids[k]))
                    chunk = self.chunks.get(key)
                    if chunk is None:
                        chunk = loaded[c]
                        self.chunks[key] = chunk
                        self.used += chunk.nbytes
                    self.chunks.move_to_end(key)
                    where = order[firsts[k]:lasts[k]]
                    out[where] = chunk[rows[where] - c * size]
                while self.used > self.budget and self.chunks:
                    _, old = self.chunks.popitem(last=False)
                    self.used -= old.nbytes
        return out


class Loader:
    """Draws batches of one kind of unit from a dataset (see the module docstring for the batch layout).

    Args:
      dataset: a :class:`TrajectoryDataset` (read in its current committed state).
      batch_size: S.
      mode: ``"transition"``, ``"window"`` (L consecutive steps of one trajectory), ``"window_across"``
        (L consecutive steps of the selected trajectories laid end to end) or ``"trajectory"`` (whole
        trajectories padded to L, by default the longest selected).
      length: L (required by the window modes).
      trajectories: indices of the trajectories to draw from (e.g. a split); all by default.
      memory_budget: bytes of device memory the selected data may take to be loaded whole (default: half of
        the device's memory, or 2 GiB); past it, batches stream from disk with that much chunk cache.
      prefetch: batches read ahead by :meth:`batches` when streaming.
    """

    def __init__(self, dataset: Any, batch_size: int, *, mode: str = "transition",
                 length: int | None = None, trajectories: Sequence[int] | None = None,
                 memory_budget: int | None = None, prefetch: int = 2):
        if mode not in MODES:
            raise DatasetError(f"unknown sampling mode {mode!r}; valid modes are {list(MODES)}")
        if int(batch_size) < 1:
            raise DatasetError(f"batch_size must be positive, got {batch_size}")
        n = dataset.num_trajectories()
        selected = np.arange(n) if trajectories is None else np.asarray(trajectories, np.int64).reshape(-1)
        if selected.size == 0:
            raise DatasetError(f"nothing to sample: the dataset at {dataset.path!r} has no (selected) trajectories")
        if selected.min() < 0 or selected.max() >= n:
            raise DatasetError(f"trajectory indices must lie in [0, {n}), got {selected.min()}..{selected.max()}")
        lengths = dataset.lengths()[selected]
        if mode == "transition":
            length = 1
        elif mode == "trajectory":
            length = int(lengths.max()) if length is None else int(length)
        elif length is None or int(length) < 1:
            raise DatasetError(f"mode={mode!r} needs a positive length, got {length!r}")
        length = int(length)
        longest = int(lengths.max()) if mode == "window" else int(lengths.sum())
        if mode in ("window", "window_across") and longest < length:
            raise DatasetError(f"no window of length {length}: the selected trajectories have at most {longest} "
                               f"{'steps each' if mode == 'window' else 'steps in all'}")
        self.dataset, self.mode, self.batch_size, self.length = dataset, mode, int(batch_size), length
        self.selected, self.prefetch = selected, int(prefetch)
        self._lengths = jnp.asarray(lengths, jnp.int32)
        steps_before = np.concatenate([[0], np.cumsum(dataset.lengths())])[selected]
        self._step_start = steps_before.astype(np.int64)  # global step row of each selected trajectory's step 0
        self.nbytes = self._bytes(lengths)
        budget = _default_budget() if memory_budget is None else int(memory_budget)
        self.in_memory = self.nbytes <= budget
        if self.in_memory:
            self._device = self._load()
        else:
            self._cache = _ChunkCache(budget)

    # ------------------------------------------------------------------------------------------ sizes and loading
    def _fields(self):
        for group in GROUPS:
            for name, f in getattr(self.dataset.schema, group).items():
                yield group, f"{group}/{name}", f
        for name, f in STEP_FIELDS.items():
            yield "step", f"step/{name}", f

    def _bytes(self, lengths: np.ndarray) -> int:
        steps = int(lengths.sum())
        rows = {"observation": steps + lengths.size, "step": steps, "trajectory": lengths.size}
        return sum(rows[ROWS_PER[group]] * f.itemsize for group, _, f in self._fields())

    def _rows(self, kind: str, rank: np.ndarray, step: np.ndarray) -> np.ndarray:
        """Global row numbers of the arrays of ``kind`` for (rank, step) pairs."""
        if kind == "trajectory":
            return self.selected[rank]
        rows = self._step_start[rank] + step
        return rows + self.selected[rank] if kind == "observation" else rows

    def _load(self) -> dict[str, jax.Array]:
        """Reads the selected trajectories' rows (laid end to end) onto the device."""
        lengths = np.asarray(self._lengths, np.int64)
        rows = {"observation": self._rows("observation", *_ranges(lengths + 1)),
                "step": self._rows("step", *_ranges(lengths)), "trajectory": self.selected}
        out = {}
        for group, name, _ in self._fields():
            array, wanted = self.dataset.array(name), rows[ROWS_PER[group]]
            if wanted[-1] - wanted[0] + 1 == wanted.size:  # contiguous (e.g. all trajectories): one read
                data = read_rows(array, int(wanted[0]), int(wanted[-1]) + 1)
            else:
                data = _ChunkCache(0).rows(array, wanted)
            out[name] = jax.device_put(data)
        return out

    # ------------------------------------------------------------------------------------------ sampling
    def indices(self, key: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        """``(rank, step, mask)`` of the batch drawn with ``key`` (see :func:`draw_indices`)."""
        return draw_indices(key, self._lengths, self.mode, self.batch_size, self.length)

    def sample(self, key: jax.Array) -> dict[str, Any]:
        """The batch drawn with ``key``, on device."""
        rank, step, mask = self.indices(key)
        if self.in_memory:
            batch = gather_device(self._device, rank, step, mask, jnp.asarray(self._lengths),
                                   jnp.asarray(self.selected, jnp.int32), self._layout())
        else:
            batch = jax.device_put(self._gather_disk(np.asarray(rank), np.asarray(step), np.asarray(mask)))
        if self.mode == "transition":
            batch = jax.tree_util.tree_map(lambda x: x[:, 0], batch)
        return batch

    def batches(self, key: jax.Array, num_batches: int | None = None) -> Iterator[dict[str, Any]]:
        """Batch i drawn with ``jax.random.fold_in(key, i)``, for i = 0, 1, ... (forever by default)."""
        keys = (jax.random.fold_in(key, i)
                for i in (range(num_batches) if num_batches is not None else itertools.count()))
        if self.in_memory or self.prefetch < 1:
            yield from map(self.sample, keys)
            return
        with concurrent.futures.ThreadPoolExecutor(1) as pool:
            pending = collections.deque(pool.submit(self.sample, k) for k in itertools.islice(keys, self.prefetch))
            while pending:
                batch = pending.popleft().result()
                following = next(keys, None)
                if following is not None:
                    pending.append(pool.submit(self.sample, following))
                yield batch

    def _layout(self) -> tuple:
        return tuple((group, name, f.output_key) for group, name, f in self._fields())

    def _gather_disk(self, rank: np.ndarray, step: np.ndarray, mask: np.ndarray) -> dict[str, Any]:
        flat_rank, flat_step = rank.reshape(-1), step.reshape(-1)
        columns = {}
        for group, name, _ in self._fields():
            kind = ROWS_PER[group]
            rows = self._rows(kind, flat_rank, flat_step)
            array = self.dataset.array(name)
            # Raw arrays: read just the rows (runs of them); the page cache keeps what is hot. Others: whole
            # chunks (zarr decodes a chunk at once), kept in an LRU cache within the budget.
            read = read_row_set if is_raw(array) else self._cache.rows
            if group == "observation":
                both = read(array, np.concatenate([rows, rows + 1]))
                columns[name] = (both[:rows.size], both[rows.size:])
            else:
                columns[name] = read(array, rows)
        lengths = np.asarray(self._lengths)
        return _assemble(columns, rank, step, mask, lengths, self.selected, self._layout(), np)


def _ranges(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rank, index)`` enumerating ``index in range(counts[rank])`` for every rank, in order."""
    rank = np.repeat(np.arange(counts.size), counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return rank, np.arange(rank.size) - starts[rank]


def _assemble(columns: dict, rank, step, mask, lengths, selected, layout, xp) -> dict[str, Any]:
    """Builds the batch dict from per-array columns of flat rows (numpy or jax.numpy via ``xp``)."""
    shape = rank.shape

    def shaped(x):
        x = x.reshape(shape + x.shape[1:])
        return xp.where(mask.reshape(shape + (1,) * (x.ndim - 2)), x, xp.zeros((), x.dtype))

    batch: dict[str, Any] = {"observation": {}, "next_observation": {}, "action": {}, "goal": {}}
    for group, name, key in layout:
        if group == "observation":
            batch["observation"][key], batch["next_observation"][key] = map(shaped, columns[name])
        elif group == "step":
            batch[name.split("/")[1]] = shaped(columns[name])
        else:
            batch[group][key] = shaped(columns[name])
    batch.update(mask=mask, first=mask & (step == 0), last=mask & (step == lengths[rank] - 1),
                 trajectory=xp.where(mask, selected[rank], 0).astype(xp.int32), step=step.astype(xp.int32))
    return batch


@functools.partial(jax.jit, static_argnames=("layout",))
def gather_device(data: dict, rank, step, mask, lengths, selected, layout) -> dict[str, Any]:
    """The batch of the draw ``(rank, step, mask)`` (:func:`draw_indices`) from arrays on device (jittable).

    Args:
      data: ``"group/name"`` -> the selected trajectories' rows laid end to end (observations T_i + 1 a
        trajectory, steps T_i, goals 1).
      lengths: int32 (N,), the selected trajectories' lengths; ``selected``: int32 (N,), their dataset indices.
      layout: static tuple of ``(group, "group/name", batch key)`` for every array of ``data``.
    """
    step_start = jnp.concatenate([jnp.zeros((1,), jnp.int32), jnp.cumsum(lengths)])[rank]
    flat = {"step": (step_start + step).reshape(-1), "observation": (step_start + rank + step).reshape(-1),
            "trajectory": rank.reshape(-1)}
    columns = {}
    for group, name, _ in layout:
        rows = flat[ROWS_PER[group]]
        columns[name] = (data[name][rows], data[name][rows + 1]) if group == "observation" else data[name][rows]
    return _assemble(columns, rank, step, mask, lengths, selected, layout, jnp)
