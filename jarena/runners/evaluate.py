"""``evaluate`` and ``validate``: every episode of a split, in parallel, in one compiled call."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jarena import distributed
from jarena.core.agent import Agent
from jarena.core.arena import Arena
from jarena.core.batching import batch_reset
from jarena.core.episodes import check_episode_ids
from jarena.core.types import ArenaParams
from jarena.render.record import check_video, write_episodes
from jarena.runners.loop import frozen_step
from jarena.runners.results import EvalResult
from jarena.runners.run import check_count

PyTree = Any


@functools.lru_cache(maxsize=64)
def _compiled_episodes(agent: Agent, arena: Arena, num: int, max_steps: int, params_axis: int | None,
                       filmed: int = 0, mesh=None, key_impl=None, stacked: bool = False):
    """A jitted ``(key_data, agent_state, params, ids) -> per-episode arrays`` for ``num`` episodes.

    With ``filmed > 0`` it also keeps the physics states of the first ``filmed`` arenas at every step,
    ``physics``: (max_steps + 1, filmed, ...), the reset state first (frozen after an episode ends). With a
    ``mesh`` of several devices the episodes are split over them (``num`` divides evenly). With ``stacked``, the
    agent state's leaves have a leading policy axis (P, ...) and every output gains one: each policy runs the same
    episodes with the same key, all in one program.
    """
    split = None if mesh is None else distributed.batch_shardings
    constrain = ((lambda tree: jax.lax.with_sharding_constraint(tree, split(tree, mesh, num))) if split
                 else (lambda tree: tree))

    def episodes(key_data, agent_state, params, ids):
        key = jax.random.wrap_key_data(key_data, impl=key_impl)
        state, info = batch_reset(arena, None, num, params, params_axis=params_axis, episodes=ids)
        state, info, agent_state = constrain((state, info, agent_state))
        zeros = jnp.zeros((num,), jnp.float32)
        film = None
        if filmed:
            film = jax.tree_util.tree_map(
                lambda x: jnp.zeros((max_steps + 1, filmed) + x.shape[1:], x.dtype).at[0].set(x[:filmed]),
                state.physics)
        carry = (state, info, agent_state, jnp.zeros((num,), bool), zeros, jnp.zeros((num,), jnp.int32),
                 jnp.zeros((), jnp.int32), film, jnp.zeros((num,), jnp.int32))

        def cond(c):
            done, t = c[3], c[6]
            return (t < max_steps) & ~jnp.all(done)

        def step(_, c):
            state, info, agent_state, done, ret, length, t, film, fault = c
            # past max_steps (the last block's spare steps) every episode is frozen
            state, info, agent_state, _, valid = frozen_step(agent, arena, state, info, agent_state,
                                                             jax.random.fold_in(key, t), params, params_axis,
                                                             done | (t >= max_steps))
            ret = ret + jnp.where(valid, info.reward, 0.0)  # a faulted step's reward is 0: returns stay finite
            length = length + valid.astype(jnp.int32)
            fault = fault | jnp.where(valid, info.fault, 0)  # the episode's faults (the step that ended it)
            state, info, agent_state = constrain((state, info, agent_state))
            if filmed:
                film = jax.tree_util.tree_map(lambda f, x: f.at[t + 1].set(x[:filmed], mode="drop"), film,
                                              state.physics)
            return state, info, agent_state, done | info.done, ret, length, t + 1, film, fault

        # on a mesh, "is every episode done?" is an all-reduce across the devices: asked once per block of steps
        block = steps_per_check(max_steps, 1 if mesh is None else mesh.devices.size)
        carry = jax.lax.while_loop(cond, (lambda c: step(0, c)) if block == 1 else
                                   (lambda c: jax.lax.fori_loop(0, block, step, c)), carry)
        state, info, agent_state, done, ret, length, _, film, fault = carry
        # the per-episode results stay split over the devices: each copies its own share to the host (a
        # replicated result would be gathered onto every device and copied out of one)
        out = constrain({"returns": ret, "lengths": length, "successes": info.success, "metrics": info.metrics,
                         "faults": fault})
        if filmed:  # whole on every device, so that each process holds a copy (see run_episodes)
            out["physics"] = distributed.replicate(film)
        return out

    return jax.jit(jax.vmap(episodes, in_axes=(None, 0, None, None)) if stacked else episodes)


def steps_per_check(max_steps: int, devices: int, most: int = 8) -> int:
    """Steps :func:`evaluate`'s loop takes between checks that every episode has ended, on ``devices`` devices.

    On several, each check is an all-reduce across them, so the loop checks after blocks of steps: the largest
    divisor of ``max_steps`` up to ``most`` that leaves at least 32 checks, so that the steps run after the last
    episode ended are under 1/32 of ``max_steps`` (a cloth's 30 pick-and-places, each hundreds of physics steps,
    are checked after every one) and a time limit is never overrun. Measured on two H200s, 4096 brax ants per GPU:
    1.72x -> 1.93x one GPU's rate. On one device every step is checked: there blocks gained nothing for the ants
    and cost 30% for 2^20 classic cartpoles (benchmarks/RESULTS.md)."""
    if devices < 2:
        return 1
    return max(k for k in range(1, most + 1) if max_steps % k == 0 and (k == 1 or max_steps // k >= 32))


def _pad(tree: PyTree, size: int) -> PyTree:
    """``tree``'s leaves (leading axis N) padded to ``size`` rows by repeating the last."""
    return jax.tree_util.tree_map(
        lambda x: np.concatenate([np.asarray(x), np.repeat(np.asarray(x)[-1:], size - len(x), axis=0)]), tree)


def _checked_episodes(agent: Agent, arena: Arena, split: str, episodes: Any, max_steps: int | None,
                      filmed: int = 0) -> tuple[np.ndarray, int]:
    """``(episode ids as int32, max_steps)`` of an evaluation, every argument checked before anything compiles."""
    agent.check_fits(arena)  # an AgentArenaMismatch before compiling (cached per agent and arena)
    if split not in ("eval", "val"):
        raise ValueError(f"evaluate runs the fixed 'eval' or 'val' splits, got split={split!r}")
    ids = arena.episodes(split) if episodes is None else episodes
    if isinstance(ids, range):  # a split's ids, or a user's range: no Python list of them
        ids = np.arange(ids.start, ids.stop, ids.step, dtype=np.int64)
    ids = np.asarray(ids).reshape(-1)
    if ids.size == 0:
        raise ValueError(f"no episodes to evaluate in split {split!r} of arena {arena.name!r}")
    if not 0 <= int(filmed) <= ids.size:
        raise ValueError(f"cannot film {filmed} of {ids.size} episodes; choose 0 .. {ids.size}")
    check_episode_ids(ids, f"{arena.name}: evaluate")  # before the cast to int32, which would wrap 2^32 + 5 to 5
    if max_steps is not None:
        check_count(max_steps, "max_steps", "evaluate")
    max_steps = max_steps or arena.max_episode_steps
    if max_steps is None:
        raise ValueError(f"arena {arena.name!r} has no time limit; pass max_steps to evaluate")
    return ids.astype(np.int32, copy=False), int(max_steps)


def _result(agent: Agent, arena: Arena, split: str, ids: np.ndarray, out: dict) -> EvalResult:
    """The :class:`EvalResult` of one policy's per-episode host arrays ``out``."""
    return EvalResult(arena=arena.build_string or arena.name, agent=agent.name, split=split, episodes=ids,
                      returns=np.asarray(out["returns"]), lengths=np.asarray(out["lengths"]),
                      successes=np.asarray(out["successes"]),
                      metrics={k: np.asarray(v) for k, v in out["metrics"].items()},
                      faults=np.asarray(out["faults"], np.int32), has_success=arena.task.has_success)


def evaluate_policies(agent: Agent, arena: Arena, agent_states: PyTree, key: jax.Array | None = None, *,
                      split: str = "eval", episodes: Any = None, max_steps: int | None = None) -> list[EvalResult]:
    """Evaluates P policies of one agent on the same episodes in one compiled program, on one device.

    ``agent_states``: the P policies' states stacked on a leading axis (leaves (P, ...)), e.g. the trained
    policies of several seeds (:func:`jarena.train_seeds`). Policy ``p``'s result is what :func:`evaluate` gives
    with ``agent_state`` its slice and the same key (batched operations may round differently, which chaotic
    physics can grow: per-episode returns equal on classic arenas, mean returns equal to 3 decimals on an MJX
    walker); the P evaluations run as one batch of P x N arenas, meant for a device that N arenas leave idle (not
    measured on a GPU yet; on 2 CPU cores it is 0.8x as fast as P calls: ``benchmarks/evaluate_policies_speed.py``).
    Returns one :class:`EvalResult` per policy, in order.
    """
    ids, max_steps = _checked_episodes(agent, arena, split, episodes, max_steps)
    leaves = jax.tree_util.tree_leaves(agent_states)
    sizes = {np.shape(leaf)[0] if np.ndim(leaf) else None for leaf in leaves}
    if not leaves or len(sizes) != 1 or None in sizes or 0 in sizes:
        raise ValueError(f"evaluate_policies needs agent states stacked on a leading policy axis (every leaf "
                         f"(P, ...), P >= 1); got leading sizes {sorted(map(str, sizes))}")
    count = sizes.pop()
    key = jax.random.key(0) if key is None else key
    num = ids.size
    states = [agent.batch_state(jax.tree_util.tree_map(lambda x: x[p], agent_states), num) for p in range(count)]
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *states)
    episodes_fn = _compiled_episodes(agent, arena, num, max_steps, None, 0, None, jax.random.key_impl(key),
                                     stacked=True)
    out = jax.device_get(episodes_fn(np.asarray(jax.random.key_data(key)), stacked, arena.default_params(), ids))
    return [_result(agent, arena, split, ids, jax.tree_util.tree_map(lambda x: x[p], out)) for p in range(count)]


def run_episodes(agent: Agent, arena: Arena, key: jax.Array | None = None, *, agent_state: PyTree = None,
                 params: ArenaParams | None = None, params_axis: int | None = None, split: str = "eval",
                 episodes: Any = None, max_steps: int | None = None, filmed: int = 0,
                 devices: int | str | None = None) -> tuple[EvalResult, PyTree]:
    """:func:`evaluate`, also returning the physics states of the first ``filmed`` episodes on device,
    (max_steps + 1, filmed, ...) with the reset state first, or ``None`` when ``filmed == 0``."""
    ids, max_steps = _checked_episodes(agent, arena, split, episodes, max_steps, filmed)
    key = jax.random.key(0) if key is None else key
    params = arena.default_params() if params is None else params
    mesh = distributed.mesh(devices)
    count = mesh.devices.size
    num = -(-ids.size // count) * count  # padded to split evenly; the padding's results are dropped
    run_ids = _pad(ids, num) if num > ids.size else ids
    if num > ids.size and params_axis is not None:
        params = jax.tree_util.tree_map(lambda x: np.moveaxis(_pad(np.moveaxis(np.asarray(x), params_axis, 0), num),
                                                              0, params_axis), params)
    if agent_state is None:
        agent_state = agent.init(jax.random.fold_in(key, 0x1A1), arena.spec, num)
    else:
        agent_state = agent.batch_state(agent_state, num)
    if count > 1:  # host values, the same in every process, become the mesh's global inputs
        agent_state, params = distributed.fetch((agent_state, params))
    episodes_fn = _compiled_episodes(agent, arena, num, int(max_steps), params_axis, int(filmed),
                                     mesh if count > 1 else None, jax.random.key_impl(key))
    if count > 1:  # each device receives its own episodes' ids
        run_ids = jax.make_array_from_callback(run_ids.shape, distributed.batch_shardings(run_ids, mesh, num),
                                               run_ids.__getitem__)
    with distributed.tracing_on(mesh):  # each device steps its own arenas (jarena.core.batching.batch_step)
        out = episodes_fn(np.asarray(jax.random.key_data(key)), agent_state, params, run_ids)
    physics = out.pop("physics", None)  # on one process it stays on device: the renderer pulls only what it draws
    out = jax.tree_util.tree_map(lambda x: x[: ids.size], distributed.fetch(out, f"{split} episodes"))
    if physics is not None and jax.process_count() > 1:
        # The collective part ends here. Every process takes a host copy of the filmed states (replicated: no
        # data moves between processes), so that process 0 renders them alone without entering a computation
        # over arrays that span the processes, which the others would never enter.
        physics = distributed.fetch(physics, f"{split} filmed states")
    return _result(agent, arena, split, ids, out), physics


def evaluate(agent: Agent, arena: Arena, key: jax.Array | None = None, *, agent_state: PyTree = None,
             params: ArenaParams | None = None, params_axis: int | None = None, split: str = "eval",
             episodes: Any = None, max_steps: int | None = None, videos: int = 0,
             video_dir: str | Path | None = None, video_options: Any = None,
             devices: int | str | None = None) -> EvalResult:
    """Runs ``agent`` on every episode of ``split`` (or the given episode ids), all in parallel.

    Each arena runs one episode to its end (terminated or truncated) or ``max_steps`` agent steps; the
    whole evaluation is one compiled ``while_loop`` over a batch of arenas.

    Args:
      agent: any :class:`~jarena.core.agent.Agent`.
      arena: the arena.
      key: PRNG key for the agent's randomness (default ``jax.random.key(0)``).
      agent_state: the agent's state for a batch of N arenas (default: ``agent.init``).
      params: arena params, shared or per episode (see ``params_axis``).
      params_axis: ``None`` (params shared) or ``0`` (one per episode).
      split: ``eval`` or ``val``.
      episodes: explicit episode ids instead of a split's.
      max_steps: step cap (default: the arena's ``max_episode_steps``).
      videos: film the first ``videos`` episodes into ``video_dir/<split>_episode_<id>.mp4`` (the results
        are the same as without): the loop keeps their physics states on device, the frames are rendered
        on the host afterwards (in a multi-process run, by process 0 alone). The arena must render
        (``jarena.render.can_render``).
      video_dir: folder for the videos (required with ``videos``).
      video_options: a :class:`jarena.render.VideoOptions` (frame size, camera, fps, format).
      devices: split the episodes over this many devices (:func:`jarena.distributed.mesh`: ``"all"``, a
        count, or ``None``: all devices of a multi-process run, else one); the results are the same.

    Returns:
      An :class:`EvalResult` with per-episode returns, lengths, successes and metrics.
    """
    if videos:
        if video_dir is None:
            raise ValueError("evaluate(videos=N) needs a video_dir to write the videos to")
        if distributed.is_main_process():  # the process that renders: fails before compiling if it cannot
            check_video(arena, video_options, params, params_axis)
    result, physics = run_episodes(agent, arena, key, agent_state=agent_state, params=params,
                                   params_axis=params_axis, split=split, episodes=episodes, max_steps=max_steps,
                                   filmed=int(videos), devices=devices)
    if videos and distributed.is_main_process():  # in a multi-process run process 0 writes, from host copies
        paths = [Path(video_dir) / f"{split}_episode_{int(i)}" for i in result.episodes[: int(videos)]]
        write_episodes(arena, physics, result.lengths[: int(videos)], paths, video_options, params=params,
                       params_axis=params_axis)
    return result


def validate(agent: Agent, arena: Arena, key: jax.Array | None = None, **kwargs) -> EvalResult:
    """:func:`evaluate` on the validation split."""
    return evaluate(agent, arena, key, split="val", **kwargs)
