"""A contract checker that every arena must pass (run it over your own arenas too).

    from jarena.testing import check_arena
    check_arena(jarena.build_arena("classic|domain:cartpole"))

Each ``check_*`` function raises ``AssertionError`` naming the property that failed:

- ``check_jit_consistency``: jit and non-jit reset/step agree;
- ``check_no_retrace``: reset and step compile once, for new keys, states, actions and params;
- ``check_vmap``: ``jit(vmap(...))`` over keys and over params keeps the tree structure with a batch axis;
- ``check_determinism``: the same key gives a bit-identical trajectory, different keys different
  initial states, and an episode id gives the same episode whatever the key;
- ``check_rollout``: over an episode of random actions every value is finite, no step faults (see
  :mod:`jarena.core.faults`), every observation is in the observation spec, every sampled action in the
  action spec, and reset and step infos share one structure.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import Arena
from jarena.core.batching import auto_reset
from jarena.core.faults import describe

DEFAULT_STEPS = 200
DEFAULT_DETERMINISM_STEPS = 50


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(tree)
            if not jax.dtypes.issubdtype(jnp.asarray(x).dtype, jax.dtypes.prng_key)]


def _assert_trees_close(a, b, what: str, rtol=1e-5, atol=1e-5):
    chex.assert_trees_all_equal_structs(a, b)
    for x, y in zip(_leaves(a), _leaves(b), strict=True):
        if x.dtype.kind in "fc":
            np.testing.assert_allclose(x, y, rtol=rtol, atol=atol, err_msg=what)
        else:
            np.testing.assert_array_equal(x, y, err_msg=what)


def _assert_trees_identical(a, b, what: str):
    chex.assert_trees_all_equal_structs(a, b)
    for x, y in zip(_leaves(a), _leaves(b), strict=True):
        if not np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"):
            raise AssertionError(f"{what}: arrays differ\n{x}\nvs\n{y}")


def _perturbed(params, factor: float):
    """Params with every float leaf scaled by ``factor`` (same structure and dtypes)."""
    return jax.tree_util.tree_map(
        lambda x: x * jnp.asarray(factor, x.dtype) if jnp.issubdtype(jnp.asarray(x).dtype, jnp.floating) else x,
        params)


def check_jit_consistency(arena: Arena, key: jax.Array, steps: int = 2) -> None:
    params = arena.default_params()
    s_eager, i_eager = arena.reset(key, params)
    s_jit, i_jit = jax.jit(arena.reset)(key, params)
    _assert_trees_close(i_eager, i_jit, f"{arena.name}: jit and non-jit reset disagree")
    step = jax.jit(arena.step)
    for t in range(steps):
        action = arena.sample_action(jax.random.fold_in(key, t))
        s_eager, i_eager = arena.step(s_eager, action, params)
        s_jit, i_jit = step(s_jit, action, params)
        _assert_trees_close(i_eager, i_jit, f"{arena.name}: jit and non-jit step {t} disagree")


def check_no_retrace(arena: Arena, key: jax.Array) -> None:
    @jax.jit
    @chex.assert_max_traces(n=1)
    def reset(k, p):
        return arena.reset(k, p)

    @jax.jit
    @chex.assert_max_traces(n=1)
    def step(s, a, p):
        return arena.step(s, a, p)

    try:
        for i, factor in enumerate([1.0, 1.01, 0.99]):
            params = _perturbed(arena.default_params(), factor)
            state, _ = reset(jax.random.fold_in(key, i), params)
            for t in range(2):
                state, _ = step(state, arena.sample_action(jax.random.fold_in(key, 100 * i + t)), params)
    except AssertionError as e:
        raise AssertionError(f"{arena.name}: reset or step retraced on new keys, states, actions or params: {e}") from e
    finally:
        chex.clear_trace_counter()


def check_vmap(arena: Arena, key: jax.Array, batch: int = 3) -> None:
    params = arena.default_params()
    keys = jax.random.split(key, batch)
    states, infos = jax.jit(jax.vmap(arena.reset, in_axes=(0, None)))(keys, params)
    _, single = jax.eval_shape(arena.reset, keys[0], params)  # the unbatched structure and shapes
    chex.assert_trees_all_equal_structs(single, infos)
    for leaf, one in zip(jax.tree_util.tree_leaves(infos), jax.tree_util.tree_leaves(single), strict=True):
        assert leaf.shape == (batch,) + one.shape, f"{arena.name}: vmapped reset leaf shape {leaf.shape}"
    actions = jax.vmap(arena.sample_action)(keys)
    _, stepped = jax.jit(jax.vmap(arena.step, in_axes=(0, 0, None)))(states, actions, params)
    chex.assert_trees_all_equal_structs(single, stepped)

    batched_params = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs),
                                            *[_perturbed(params, 1.0 + 0.01 * i) for i in range(batch)])
    # one key per arena, as batch_reset(..., params_axis=0) gives (a host arena opens one simulator per key)
    states, infos = jax.jit(jax.vmap(arena.reset, in_axes=(0, 0)))(keys, batched_params)
    _, stepped = jax.jit(jax.vmap(arena.step, in_axes=(0, 0, 0)))(states, actions, batched_params)
    for leaf, one in zip(jax.tree_util.tree_leaves(stepped), jax.tree_util.tree_leaves(single), strict=True):
        assert leaf.shape == (batch,) + one.shape, f"{arena.name}: vmap over params gives leaf shape {leaf.shape}"


def _trajectory(arena: Arena, steps: int):
    @jax.jit
    def rollout(key):
        params = arena.default_params()
        state, info = arena.reset(key, params)

        def body(carry, t):
            state, _ = carry
            action = arena.sample_action(jax.random.fold_in(key, t))
            state, info = auto_reset(arena, state, action, params)
            return (state, info), (info, action)

        (_, _), (infos, actions) = jax.lax.scan(body, (state, info), jnp.arange(steps))
        return info, infos, actions

    return rollout


def check_determinism(arena: Arena, key: jax.Array, steps: int | None = None) -> None:
    """The same key gives the same rollout of ``steps`` random actions (default 50, or two whole episodes and a
    step where episodes are shorter, so that two auto-resets are crossed: a cloth's step is a pick-and-place of
    some 70 physics steps); another key gives another start; an episode id fixes the start whatever the key."""
    if steps is None:
        steps = min(DEFAULT_DETERMINISM_STEPS, 2 * arena.max_episode_steps + 1) if arena.max_episode_steps else \
            DEFAULT_DETERMINISM_STEPS
    rollout = _trajectory(arena, steps)
    first = rollout(key)
    second = rollout(key)
    _assert_trees_identical(first, second, f"{arena.name}: same key, different trajectories")
    other = rollout(jax.random.fold_in(key, 1))
    if all(np.array_equal(a, b) for a, b in zip(_leaves(first[0].observation), _leaves(other[0].observation),
                                                strict=True)):
        raise AssertionError(f"{arena.name}: different keys gave identical initial observations")
    # two separate traces, so that a task reading host state while tracing (a counter, the clock) shows up
    by_id_1, by_id_2 = (jax.jit(lambda k: arena.reset(k, episode=7)[1])(jax.random.key(i)) for i in (1, 2))
    _assert_trees_identical(by_id_1, by_id_2, f"{arena.name}: episode 7 depends on the key, not only its id")


def check_rollout(arena: Arena, key: jax.Array, steps: int | None = None) -> None:
    steps = steps or min(arena.max_episode_steps or DEFAULT_STEPS, DEFAULT_STEPS * 2)
    initial, infos, actions = _trajectory(arena, steps)(key)
    chex.assert_trees_all_equal_structs(initial.replace(final=None), infos.replace(final=None))
    # Arena.step zeroes a faulted step's non-finite observation and reward, so a blow-up shows in its fault
    fault = np.asarray(infos.fault)
    if np.any(fault != 0):
        t = int(np.argmax(fault != 0))
        raise AssertionError(f"{arena.name}: step {t} of random valid actions faulted: {describe(fault[t])}")
    for leaf in jax.tree_util.tree_leaves((initial, infos)):
        if jnp.issubdtype(leaf.dtype, jnp.floating) and not np.all(np.isfinite(np.asarray(leaf))):
            raise AssertionError(f"{arena.name}: non-finite values in info over {steps} steps")
    obs_spec, act_spec = arena.observation_spec, arena.action_spec
    act_spec.validate(jax.tree_util.tree_map(lambda x: x[0], actions), "sampled action")
    if not bool(obs_spec.contains(initial.observation)):
        raise AssertionError(f"{arena.name}: initial observation outside {obs_spec}")
    inside = jax.vmap(obs_spec.contains)(infos.observation)
    if not bool(jnp.all(inside)):
        t = int(np.argmin(np.asarray(inside)))
        bad = jax.tree_util.tree_map(lambda x: x[t], infos.observation)
        raise AssertionError(f"{arena.name}: observation at step {t} outside its spec {obs_spec}: {bad}")
    terminal_inside = jax.vmap(obs_spec.contains)(infos.final.observation)
    if not bool(jnp.all(jnp.where(infos.done, terminal_inside, True))):
        raise AssertionError(f"{arena.name}: a terminal observation is outside its spec {obs_spec}")
    if not bool(jnp.all(jax.vmap(act_spec.contains)(actions))):
        raise AssertionError(f"{arena.name}: sampled actions outside the action spec {act_spec}")


CHECKS = (check_jit_consistency, check_no_retrace, check_vmap, check_determinism, check_rollout)


def check_arena(arena: Arena, key: jax.Array | None = None) -> None:
    """Runs every contract check on ``arena``; raises ``AssertionError`` on the first failure."""
    key = jax.random.key(0) if key is None else key
    for check in CHECKS:
        check(arena, key)
