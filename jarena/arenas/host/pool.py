"""The host side of a host arena: batches of live simulators, each a vector env stepped as one.

Each ``batch_reset`` of a host arena (a ``vmap`` of ``reset`` over B arenas) opens a *batch*: a vector env of B
simulators, reset with one seed each, whose id and slots the arenas' states carry. Steps of those states step
that vector env; an arena whose episode ended restarts in place (``restart``, masked). Several batches can live
at once (a training batch and the validation episodes run between its updates); the least recently used one
is closed when more than ``max_batches`` are open, and its vector env is kept to serve a later batch of the
same size (simulators can be slow to make). A state of a closed batch is an error that says so.

A simulator whose episode ended is never stepped on: until its arena restarts it (an arena stepped past the
end of its episode, as :func:`jarena.evaluate` does while others finish), each step returns the ended step's
observation and flags again with zero reward, and the simulator is reset out of sight so that the vector env
can step the others.
"""

from __future__ import annotations

import collections
import dataclasses
import threading
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

PyTree = Any


class VectorEnv(Protocol):
    """What a batch needs of a vector env: Gymnasium's ``VectorEnv`` with ``AutoresetMode.DISABLED``."""

    num_envs: int

    def reset(self, *, seed: list[int] | None = None, options: dict | None = None) -> tuple[Any, dict]: ...

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict]: ...

    def close(self) -> None: ...


class HostArenaError(RuntimeError):
    """A host arena was used in a way its simulators cannot follow (a closed batch, mixed batches)."""


@dataclasses.dataclass
class Batch:
    """One open batch: its vector env and, per simulator, what its arena saw last."""

    env: VectorEnv
    observation: PyTree  # (B, ...) the last observation returned for each slot
    frozen: np.ndarray  # (B,) bool: the arena's episode ended and was not restarted (its last step repeats)
    ended: np.ndarray  # (B,) bool: the simulator's episode ended and it was not reset since
    terminated: np.ndarray  # (B,) bool: flags of the last step, repeated while frozen
    truncated: np.ndarray


def _rows(tree: PyTree, index: np.ndarray) -> PyTree:
    if isinstance(tree, dict):
        return {k: _rows(v, index) for k, v in tree.items()}
    return np.asarray(tree)[index]


def _set_rows(tree: PyTree, index: np.ndarray, values: PyTree) -> PyTree:
    if isinstance(tree, dict):
        return {k: _set_rows(tree[k], index, values[k]) for k in tree}
    out = np.array(tree, copy=True)
    out[index] = np.asarray(values)[index]
    return out


class EnvPool:
    """Open batches of simulators of one host arena (see the module docstring); thread-safe.

    Args:
      make: ``B -> VectorEnv`` of B fresh simulators, which must not reset themselves
        (``AutoresetMode.DISABLED``) and accept ``reset(seed=[...], options={"reset_mask": mask})``.
      observe: ``(vector env observation) -> pytree of numpy arrays (B, ...)`` in the arena's dtypes.
      cast_action: ``(actions (B, ...)) -> what the vector env's ``step`` takes``.
      max_batches: how many batches may be open at once.
      name: the arena's name, for messages.
    """

    def __init__(self, make: Callable[[int], VectorEnv], observe: Callable[[Any], PyTree],
                 cast_action: Callable[[np.ndarray], Any], max_batches: int = 4, name: str = "host arena"):
        if max_batches < 1:
            raise ValueError(f"max_batches must be at least 1, got {max_batches}")
        self._make, self._observe, self._cast_action = make, observe, cast_action
        self.max_batches, self.name = max_batches, name
        self._open: collections.OrderedDict[int, Batch] = collections.OrderedDict()  # least recently used first
        self._spare: dict[int, list[VectorEnv]] = collections.defaultdict(list)
        self._next_id = 0
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ the three host calls
    def start(self, seeds: np.ndarray) -> tuple[np.ndarray, PyTree]:
        """Opens a batch of ``len(seeds)`` simulators reset with ``seeds``: ``(handles, observations)``, where
        ``handles`` (B, 2) int32 holds each simulator's batch id and slot."""
        seeds = np.asarray(seeds)
        size = len(seeds)
        with self._lock:
            env = self._spare[size].pop() if self._spare[size] else self._make(size)
            if env.num_envs != size:
                raise HostArenaError(f"{self.name}: asked for {size} simulators, its vector env has {env.num_envs}")
            observation = self._observe(env.reset(seed=[int(s) for s in seeds])[0])
            batch_id = self._next_id
            self._next_id = (self._next_id + 1) % (1 << 31)
            zeros = np.zeros(size, bool)
            self._open[batch_id] = Batch(env, observation, zeros.copy(), zeros.copy(), zeros.copy(), zeros.copy())
            while len(self._open) > self.max_batches:
                _, old = self._open.popitem(last=False)
                self._spare[old.env.num_envs].append(old.env)
                self._close_spares(keep=self.max_batches)
        handles = np.stack([np.full(size, batch_id, np.int32), np.arange(size, dtype=np.int32)], axis=1)
        return handles, observation

    def step(self, batch_ids: np.ndarray, slots: np.ndarray, actions: PyTree) -> tuple[PyTree, np.ndarray]:
        """Steps every simulator of one batch: ``(observations, outcome)`` in the order of ``slots`` (a
        permutation of the batch's slots), where ``outcome`` (B, 3) float32 holds reward, terminated and
        truncated (one array: each array a host call returns costs time)."""
        with self._lock:
            batch, order = self._batch(batch_ids, slots, "step")
            if batch.ended.any():  # an ended simulator is reset out of sight before the vector env steps it
                batch.env.reset(options={"reset_mask": batch.ended.copy()})
                batch.ended[:] = False
            if order is not None:
                actions = _rows(actions, np.argsort(order))  # the vector env's order
            actions = self._cast_action(actions)
            observation, reward, terminated, truncated, _ = batch.env.step(actions)
            observation = self._observe(observation)
            reward = np.asarray(reward, np.float32)
            terminated, truncated = np.asarray(terminated, bool), np.asarray(truncated, bool)
            batch.ended |= terminated | truncated
            frozen = batch.frozen
            if frozen.any():  # arenas stepped past the end of their episode see that end again
                observation = _set_rows(observation, frozen, batch.observation)
                reward = np.where(frozen, np.float32(0), reward)
                terminated = np.where(frozen, batch.terminated, terminated)
                truncated = np.where(frozen, batch.truncated, truncated)
            batch.frozen |= terminated | truncated
            batch.observation, batch.terminated, batch.truncated = observation, terminated, truncated
            outcome = np.stack([reward, terminated, truncated], axis=1).astype(np.float32)
            if order is not None:
                observation, outcome = _rows(observation, order), outcome[order]
            return observation, outcome

    def restart(self, batch_ids: np.ndarray, slots: np.ndarray, seeds: np.ndarray, mask: np.ndarray) -> PyTree:
        """Resets the simulators where ``mask`` with ``seeds``; returns every slot's observation."""
        with self._lock:
            batch, order = self._batch(batch_ids, slots, "restart")
            mask, seeds = np.asarray(mask, bool), np.asarray(seeds)
            if order is not None:
                inverse = np.argsort(order)
                mask, seeds = mask[inverse], seeds[inverse]
            if mask.any():
                observation = self._observe(batch.env.reset(seed=[int(s) for s in seeds],
                                                            options={"reset_mask": mask.copy()})[0])
                batch.observation = _set_rows(batch.observation, mask, observation)
                batch.frozen[mask] = batch.ended[mask] = False
                batch.terminated[mask] = batch.truncated[mask] = False
            return batch.observation if order is None else _rows(batch.observation, order)

    # ------------------------------------------------------------------ bookkeeping
    def _batch(self, batch_ids: np.ndarray, slots: np.ndarray, what: str) -> tuple[Batch, np.ndarray | None]:
        """The open batch that ``batch_ids`` name (one id), made most recently used, and ``slots`` checked:
        ``None`` when they are the batch's slots in order, else the permutation."""
        batch_id = int(batch_ids[0])
        if np.any(batch_ids != batch_id):
            raise HostArenaError(f"{self.name}: one {what} mixes arenas of different batches "
                                 f"{np.unique(batch_ids).tolist()}; a host arena steps the arenas of one batch_reset "
                                 "together")
        if not 0 <= batch_id < self._next_id:
            raise HostArenaError(
                f"{self.name}: batch {batch_id} was never opened in this process: a host arena's state is a handle on "
                "simulators of the process that reset it, so a state restored from a checkpoint or made elsewhere "
                "cannot step; reset the arenas (batch_reset) in this process")
        if batch_id not in self._open:
            raise HostArenaError(
                f"{self.name}: its batch {batch_id} was closed: at most max_batches={self.max_batches} batches of "
                f"simulators stay open and {self.max_batches} newer ones were opened (each batch_reset opens one); "
                "raise max_batches (from_gymnasium(..., max_batches=N), or gym|...,max_batches:N)")
        self._open.move_to_end(batch_id)
        batch = self._open[batch_id]
        slots = np.asarray(slots)
        if len(slots) == batch.env.num_envs and np.array_equal(slots, np.arange(len(slots))):
            return batch, None  # the usual case: the batch as batch_reset made it
        if len(np.unique(slots)) < len(slots):
            raise HostArenaError(f"{self.name}: a {what} got several copies of one arena of batch {batch_id} (slots "
                                 f"{slots.tolist()}), which share one simulator: reset each arena with its own key "
                                 "(batch_reset), not one key broadcast over a vmap")
        if len(slots) != batch.env.num_envs or not np.array_equal(np.sort(slots), np.arange(batch.env.num_envs)):
            raise HostArenaError(f"{self.name}: a {what} got {len(slots)} arenas of batch {batch_id}, which holds "
                                 f"{batch.env.num_envs}: a host arena steps every arena of its batch together "
                                 "(in any order), never a subset or a sharded part")
        return batch, slots

    def _close_spares(self, keep: int) -> None:
        spares = [env for envs in self._spare.values() for env in envs]
        for env in spares[: max(len(spares) - keep, 0)]:
            self._spare[env.num_envs].remove(env)
            env.close()

    def close(self) -> None:
        """Closes every simulator, open or spare."""
        with self._lock:
            for batch in self._open.values():
                batch.env.close()
            for envs in self._spare.values():
                for env in envs:
                    env.close()
            self._open.clear()
            self._spare.clear()
