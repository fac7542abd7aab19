"""jarena arenas for the Gymnasium ecosystem: one arena as a ``gymnasium.Env``, a batch as a
``gymnasium.vector.VectorEnv`` stepped in one compiled call.

Observations are the arena's observation dict as a ``spaces.Dict``, or, for an arena with one observation
key (``classic|domain:cartpole``'s ``state``), that array alone, as Gymnasium's own environments give it
(``flatten=False`` keeps the dict). Seeds map to jarena's keys: ``reset(seed=s)`` starts from
``jax.random.key(s)``, later resets draw their keys from the env's ``np_random``, so a seeded env is as
repeatable as any Gymnasium env; ``reset(options={"episode": i})`` starts jarena's episode ``i`` (the
fixed validation and evaluation episodes, ``arena.episodes("eval")``). The vector env resets finished
arenas in the same step (Gymnasium's ``AutoresetMode.SAME_STEP``): the returned observation is the new
episode's, and ``info["final_obs"]`` and ``info["final_info"]`` hold the finished one's (with
``info["_final_obs"]`` marking where), as Gymnasium's vector envs do.

``step`` checks actions on the host before stepping and raises :class:`InvalidAction` for one outside the
action space, as Gymnasium's own environments do; ``ArenaEnv.step`` after an episode ended (terminated or
truncated) raises ``gymnasium.error.ResetNeeded`` until ``reset()``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import gymnasium
import jax
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from jarena.core import spec as specs
from jarena.core.arena import Arena
from jarena.core.batching import batch_reset, batch_step
from jarena.core.types import ArenaParams, Info
from jarena.interop.host_values import SEED_RANGE, action_dtypes, cast_action
from jarena.render.frames import renderer
from jarena.render.video import control_timestep


def _box(spec: specs.Box) -> spaces.Box:
    return spaces.Box(low=spec.low.astype(spec.dtype), high=spec.high.astype(spec.dtype), shape=spec.shape,
                      dtype=spec.dtype)


def _discrete(spec: specs.Discrete) -> spaces.Discrete:
    return spaces.Discrete(int(spec.n))


def _dict(spec: specs.Dict) -> spaces.Dict:
    return spaces.Dict({k: space(v) for k, v in spec.spaces.items()})


def _tuple(spec: specs.Tuple) -> spaces.Tuple:
    return spaces.Tuple(tuple(space(v) for v in spec.spaces))


#: How each jarena spec type becomes a Gymnasium space.
SPACES: dict[type, Callable[[Any], spaces.Space]] = {specs.Box: _box, specs.Discrete: _discrete,
                                                     specs.Dict: _dict, specs.Tuple: _tuple}


def space(spec: specs.Spec) -> spaces.Space:
    """The Gymnasium space of a jarena spec (:data:`SPACES`)."""
    convert = SPACES.get(type(spec))
    if convert is None:
        raise TypeError(f"no Gymnasium space for spec {spec!r}; convertible: {', '.join(t.__name__ for t in SPACES)}")
    return convert(spec)


def _single_key(arena: Arena, flatten: bool) -> str | None:
    keys = list(arena.observation_spec.spaces)
    return keys[0] if flatten and len(keys) == 1 else None


def _observation_space(arena: Arena, key: str | None) -> spaces.Space:
    return space(arena.observation_spec.spaces[key] if key is not None else arena.observation_spec)


def _observation(observation: dict, key: str | None) -> Any:
    """The Gymnasium observation of host (numpy) ``observation``: its one array, or the dict."""
    return observation[key] if key is not None else observation


def _info(info: Info, index: Any = ()) -> dict[str, Any]:
    """The Gymnasium info of one arena (``index`` into a batch) of a host (numpy) ``info``: episode id, step,
    success, reward terms and metrics, and the fault bitmask (0: none)."""
    def take(x):
        return x[index]

    return {"episode_id": int(take(info.episode)), "step": int(take(info.step)), "success": bool(take(info.success)),
            "fault": int(take(info.fault)), "reward_terms": {k: float(take(v)) for k, v in info.reward_terms.items()},
            "metrics": {k: float(take(v)) for k, v in info.metrics.items()}}


class InvalidAction(gymnasium.error.InvalidAction, AssertionError, ValueError):
    """An action outside the exported action space, raised by ``step`` before the arena steps (an
    ``AssertionError``, as Gymnasium's CartPole-v1 raises, and a ``ValueError``).

    Discrete: an integer (Python int, numpy integer scalar or 0-d array; not a float or bool) in range.
    Box: an array of the space's shape (floats or integers for a float Box) of finite values: NaN and inf
    raise, while finite values outside ``[low, high]`` are clipped by the arena, as Gymnasium's Pendulum-v1
    and MountainCarContinuous-v0 clip them. Dict and Tuple: each entry by these rules. The vector env
    applies them to the action of every env (a leading batch axis).
    """


#: The array dtype kinds (``np.dtype.kind``) a Box of each kind takes: a float Box also takes integers.
_BOX_KINDS = {"f": "iuf", "i": "iu", "u": "iu", "b": "b"}


def _as(shape: tuple[int, ...]) -> str:
    return "a scalar" if shape == () else f"an array of shape {shape}"


def _leaf_problem(space: spaces.Space, x: np.ndarray, batch: tuple[int, ...]) -> tuple[str, Any] | None:
    """``None`` if host array ``x`` holds actions (of batch shape ``batch``) of leaf ``space``, else why not
    and which ones: a boolean array of shape ``batch``, or ``None`` when ``x``'s shape or dtype is wrong."""
    shape = batch + space.shape
    if isinstance(space, spaces.Discrete):
        first, last = int(space.start), int(space.start + space.n - 1)
        valid = f"valid actions are the integers {first} to {last}"
        if x.dtype.kind not in "iu" or x.shape != shape:
            return f"{valid}, as {_as(shape)} of an integer dtype; got {x.dtype} of shape {x.shape}", None
        bad = (x < first) | (x > last)
        return (valid, bad) if bad.any() else None
    if isinstance(space, spaces.Box):
        if x.dtype.kind not in _BOX_KINDS[space.dtype.kind] or x.shape != shape:
            dtype = {"f": "a float or integer", "b": "a bool"}.get(space.dtype.kind, "an integer")
            return f"expected {_as(shape)} of {dtype} dtype; got {x.dtype} of shape {x.shape}", None
        if space.dtype.kind == "f":
            bad = ~np.isfinite(x).reshape(batch + (-1,)).all(-1)
            if bad.any():
                return "values must be finite, not NaN or inf (finite values outside the bounds are clipped)", bad
    return None


def _check_action(space: spaces.Space, action: Any, batch: tuple[int, ...] = (), name: str = "action") -> None:
    """Raises :class:`InvalidAction` unless host ``action`` is in ``space`` (``batch``: the leading batch
    shape of a vector env's actions); numpy only, no device work."""
    if isinstance(space, spaces.Dict):
        if not isinstance(action, Mapping) or set(action) != set(space.spaces):
            raise InvalidAction(f"{name} {action!r} is not in the action space {space}: expected a dict with "
                                f"keys {list(space.spaces)}")
        for k, leaf in space.spaces.items():
            _check_action(leaf, action[k], batch, f"{name}[{k!r}]")
        return
    if isinstance(space, spaces.Tuple):
        if not isinstance(action, tuple | list) or len(action) != len(space.spaces):
            raise InvalidAction(f"{name} {action!r} is not in the action space {space}: expected a tuple of "
                                f"{len(space.spaces)}")
        for i, (leaf, a) in enumerate(zip(space.spaces, action, strict=True)):
            _check_action(leaf, a, batch, f"{name}[{i}]")
        return
    try:
        problem = _leaf_problem(space, np.asarray(action), batch)
    except (TypeError, ValueError) as e:  # not array-like (a ragged list)
        problem = (f"not an array ({e})", None)
    if problem is None:
        return
    reason, bad = problem
    if not batch:
        subject = f"{name} {action!r} is not in the action space {space}"
    elif bad is None:
        subject = f"{name} {action!r} are not {batch[0]} actions of the single action space {space}"
    else:
        subject = (f"{name} {action!r}: those of envs {np.flatnonzero(bad).tolist()} are not in the single "
                   f"action space {space}")
    raise InvalidAction(f"{subject}: {reason}")


class ArenaEnv(gymnasium.Env):
    """One jarena arena as a Gymnasium environment (reset and step are jitted once per env).

    Args:
      arena: the arena (its time limit truncates episodes).
      params: arena params (default: ``arena.default_params()``).
      flatten: give a one-key observation dict as its array (default); ``False`` keeps the ``Dict`` space.
      render_mode: ``None`` or ``"rgb_array"`` (frames of ``render_size``, for arenas whose dynamics render).
      render_size: ``(width, height)`` of rendered frames in pixels.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, arena: Arena, *, params: ArenaParams | None = None, flatten: bool = True,
                 render_mode: str | None = None, render_size: tuple[int, int] = (320, 240)):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if render_mode is not None:
            renderer(arena)  # a RenderError naming the arenas that render, now rather than at render()
        self.arena, self.params = arena, arena.default_params() if params is None else params
        self.render_mode, self.render_size = render_mode, tuple(render_size)
        self._key = _single_key(arena, flatten)
        self.observation_space = _observation_space(arena, self._key)
        self.action_space = space(arena.action_spec)
        self._action_dtypes = action_dtypes(arena)
        self._reset = jax.jit(arena.reset)
        self._step = jax.jit(arena.step)
        self._state, self._ended = None, None
        self.metadata = dict(self.metadata, render_fps=1.0 / control_timestep(arena))  # real time

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        episode = (options or {}).get("episode")
        if seed is not None:
            key = jax.random.key(seed)
        else:
            key = jax.random.key(int(self.np_random.integers(SEED_RANGE)))
        self._state, info = self._reset(key, self.params, episode)
        self._ended = None
        info = jax.device_get(info)  # one transfer of everything the env returns
        return _observation(info.observation, self._key), _info(info)

    def step(self, action):
        """Steps the arena; raises :class:`InvalidAction` for an action outside ``action_space``, and
        ``ResetNeeded`` before the first ``reset()`` or after an episode ended without one."""
        if self._state is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        if self._ended is not None:
            raise gymnasium.error.ResetNeeded(f"the episode ended ({self._ended}); call reset() before step()")
        _check_action(self.action_space, action)
        self._state, info = self._step(self._state, cast_action(action, self._action_dtypes), self.params)
        info = jax.device_get(info)  # one transfer of everything the env returns
        self._ended = "terminated" if info.terminated else "truncated" if info.truncated else None
        return (_observation(info.observation, self._key), float(info.reward), bool(info.terminated),
                bool(info.truncated), _info(info))

    def render(self):
        if self.render_mode is None or self._state is None:
            return None
        width, height = self.render_size
        physics = jax.tree_util.tree_map(np.asarray, self._state.physics)
        return renderer(self.arena)(physics, self.params.dynamics, width=width, height=height, camera=-1)


class ArenaVectorEnv(VectorEnv):
    """``num_envs`` copies of a jarena arena as a Gymnasium vector env, stepped (and auto-reset) in one
    compiled call; see the module docstring for the autoreset convention.

    Args:
      arena: the arena, as :class:`ArenaEnv`.
      params: arena params, as :class:`ArenaEnv`.
      flatten: as :class:`ArenaEnv`.
      num_envs: the batch size.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, arena: Arena, num_envs: int, *, params: ArenaParams | None = None, flatten: bool = True):
        if not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.arena, self.num_envs = arena, int(num_envs)
        self.params = arena.default_params() if params is None else params
        self._key = _single_key(arena, flatten)
        self.single_observation_space = _observation_space(arena, self._key)
        self.single_action_space = space(arena.action_spec)
        self.observation_space = gymnasium.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self.action_space = gymnasium.vector.utils.batch_space(self.single_action_space, self.num_envs)
        n = self.num_envs
        self._action_dtypes = action_dtypes(arena)
        self._reset = jax.jit(lambda key, params, episodes: batch_reset(arena, key, n, params, episodes=episodes))
        self._step = jax.jit(lambda state, action, params: batch_step(arena, state, action, params))
        self._state = None

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Resets all envs; ``seed`` an int (seeds env ``i`` with ``seed + i``) or one seed per env;
        ``options={"episode": ids}`` starts jarena episodes ``ids`` (one per env)."""
        if isinstance(seed, list | tuple):
            if len(seed) != self.num_envs:
                raise ValueError(f"reset got {len(seed)} seeds for {self.num_envs} envs")
            base = seed[0]
        else:
            base = seed
        self._np_random, self._np_random_seed = gymnasium.utils.seeding.np_random(base)
        episodes = (options or {}).get("episode")
        if episodes is not None:
            episodes = np.asarray(episodes, np.int32).reshape(self.num_envs)
        key = jax.random.key(int(base) if base is not None else int(self._np_random.integers(SEED_RANGE)))
        self._state, info = self._reset(key, self.params, episodes)
        info = jax.device_get(info)
        return _observation(info.observation, self._key), self._infos(info, None)

    def step(self, actions):
        """Steps (and auto-resets) every arena; raises :class:`InvalidAction` if any env's action is outside
        ``single_action_space``, and ``ResetNeeded`` before the first ``reset()``."""
        if self._state is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        _check_action(self.single_action_space, actions, (self.num_envs,), "actions")
        self._state, info = self._step(self._state, cast_action(actions, self._action_dtypes), self.params)
        info = jax.device_get(info)
        done = info.done
        return (_observation(info.observation, self._key), np.asarray(info.reward, np.float64),
                np.asarray(info.terminated), np.asarray(info.truncated), self._infos(info, done))

    def _infos(self, info: Info, done: np.ndarray | None) -> dict[str, Any]:
        """Gymnasium's vector info: arrays over envs, and where an episode ended its final observation
        (``final_obs``, an object array) and info (``final_info``)."""
        out = {"episode_id": np.asarray(info.episode), "step": np.asarray(info.step),
               "success": np.asarray(info.success), "fault": np.asarray(info.fault)}
        out.update({f"metrics/{k}": np.asarray(v) for k, v in info.metrics.items()})
        if done is not None and done.any():
            final = _observation(info.final.observation, self._key)
            final_obs = np.empty(self.num_envs, dtype=object)
            final_info = np.empty(self.num_envs, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = jax.tree_util.tree_map(lambda x, i=i: x[i], final)
                final_info[i] = {"episode_id": int(np.asarray(info.final.episode)[i])}
            out.update(final_obs=final_obs, _final_obs=done.copy(), final_info=final_info, _final_info=done.copy())
        return out


def to_gymnasium(arena: Arena, **options) -> ArenaEnv:
    """``arena`` as a ``gymnasium.Env`` (options: :class:`ArenaEnv`'s)."""
    return ArenaEnv(arena, **options)


def to_gymnasium_vector(arena: Arena, num_envs: int, **options) -> ArenaVectorEnv:
    """``num_envs`` arenas as a ``gymnasium.vector.VectorEnv`` stepped in one compiled call."""
    return ArenaVectorEnv(arena, num_envs, **options)
