"""A contract checker that every arena must pass (run it over your own arenas too).

    from jarena.testing import check_arena
    check_arena(jarena.build_arena("classic|domain:cartpole"))

Each ``check_*`` function raises ``AssertionError`` naming the property that failed:

- ``check_jit_consistency``: jit and non-jit reset/step agree (in an image or map of 10,000 elements or more,
  all but one element in 10,000: an edge pixel may flip under rounding);
- ``check_no_retrace``: reset and step compile once, for new keys, states, actions and params;
- ``check_vmap``: ``jit(vmap(...))`` over keys and over params keeps the tree structure with a batch axis;
- ``check_determinism``: the same key gives a bit-identical trajectory, different keys different
  initial states, and an episode id gives the same episode whatever the key;
- ``check_rollout``: over an episode of random actions every value is finite, no step faults (see
  :mod:`jarena.core.faults`), every observation is in the observation spec, every sampled action in the
  action spec, and reset and step infos share one structure.

The checks of one arena share its compiled programs (an MJX or cloth program takes tens of seconds to compile
on a CPU): one jitted ``reset`` and one ``step`` (jit consistency, no retrace), and one jitted rollout of a
batch of keys (vmap over keys, determinism, rollout).
"""

from __future__ import annotations

import weakref

import chex
import jax
import jax.numpy as jnp
import numpy as np

from jarena.core.arena import Arena
from jarena.core.batching import auto_reset
from jarena.core.faults import describe

DEFAULT_STEPS = 200
DEFAULT_DETERMINISM_STEPS = 50
#: Keys of the batched rollout that the vmap, determinism and rollout checks share.
ROLLOUT_BATCH = 3


def _leaves(tree):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(tree)
            if not jax.dtypes.issubdtype(jnp.asarray(x).dtype, jax.dtypes.prng_key)]


#: Arrays of at least this many elements (images, height maps) may differ at one element in this many: a pixel
#: whose ray or footprint lies on an edge flips under rounding that leaves the state within tolerance.
IMAGE_SIZE = 10_000


def _assert_trees_close(a, b, what: str, rtol=1e-5, atol=1e-5):
    """``a`` and ``b`` agree: floats within ``rtol``/``atol``, other leaves exactly; in an array of at least
    :data:`IMAGE_SIZE` elements, all but one element in :data:`IMAGE_SIZE` (edge pixels, see there)."""
    chex.assert_trees_all_equal_structs(a, b)
    for x, y in zip(_leaves(a), _leaves(b), strict=True):
        if x.size >= IMAGE_SIZE and x.shape == y.shape:
            close = (np.isclose(x, y, rtol=rtol, atol=atol, equal_nan=True) if x.dtype.kind in "fc"
                     else x == y)
            if np.count_nonzero(~close) <= x.size // IMAGE_SIZE:
                continue
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


class _Programs:
    """One arena's jitted programs that the checks share. They hold the arena weakly (the entry goes with
    the arena) and count how often reset and step are traced."""

    def __init__(self, arena: Arena):
        key = id(arena)
        self._arena = weakref.ref(arena, lambda _: _SHARED.pop(key, None))
        self.traces = {"reset": 0, "step": 0}
        self._rollouts = {}
        self.last_rollout = (None, None)  # ((steps, batch, keys), result) of the last rollout run

        def reset(key, params):
            self.traces["reset"] += 1
            return self.arena.reset(key, params)

        def step(state, action, params):
            self.traces["step"] += 1
            return self.arena.step(state, action, params)

        self.reset, self.step = jax.jit(reset), jax.jit(step)

    @property
    def arena(self) -> Arena:
        return self._arena()

    def rollout(self, steps: int, batch: int):
        """``jit(vmap(rollout, in_axes=(0, None)))(keys, params)``: each key's reset, then ``steps`` random
        actions under :func:`jarena.auto_reset`; ``(initial info, infos, actions)`` with leading axes
        ``(batch,)``, ``(batch, steps)`` and ``(batch, steps)``."""
        if (steps, batch) not in self._rollouts:
            def rollout(key, params):
                arena = self.arena
                state, info = arena.reset(key, params)

                def body(carry, t):  # the info in the carry: reset and auto-reset infos share one structure
                    state, _ = carry
                    action = arena.sample_action(jax.random.fold_in(key, t))
                    state, info = auto_reset(arena, state, action, params)
                    return (state, info), (info, action)

                (_, _), (infos, actions) = jax.lax.scan(body, (state, info), jnp.arange(steps))
                return info, infos, actions

            self._rollouts[steps, batch] = jax.jit(jax.vmap(rollout, in_axes=(0, None)))
        return self._rollouts[steps, batch]


_SHARED: dict[int, _Programs] = {}


def _programs(arena: Arena) -> _Programs:
    """The arena's shared programs (made on first use)."""
    programs = _SHARED.get(id(arena))
    if programs is None or programs.arena is not arena:
        programs = _SHARED[id(arena)] = _Programs(arena)
    return programs


def _rollout_steps(arena: Arena) -> int:
    """The shared rollout's default length: the longer of an episode (at most 400 steps; 200 without a
    horizon) and 50 steps or, where episodes are shorter, two whole episodes and a step (so that two
    auto-resets are crossed: a cloth's step is a pick-and-place of some 70 physics steps)."""
    episode = arena.max_episode_steps
    rollout = min(episode or DEFAULT_STEPS, DEFAULT_STEPS * 2)
    determinism = min(DEFAULT_DETERMINISM_STEPS, 2 * episode + 1) if episode else DEFAULT_DETERMINISM_STEPS
    return max(rollout, determinism)


def _rollout(arena: Arena, key: jax.Array, steps: int, batch: int = ROLLOUT_BATCH, again: bool = False):
    """The shared rollout from the keys ``jax.random.split(key, batch)`` with the default params. Its last
    result is kept (a crumpled cloth's rollout runs for seconds on a CPU) unless ``again``, which runs the
    program anew (the determinism check's second run)."""
    programs = _programs(arena)
    keys = jax.random.split(key, batch)
    typed = jax.dtypes.issubdtype(keys.dtype, jax.dtypes.prng_key)
    seen = (steps, batch, np.asarray(jax.random.key_data(keys) if typed else keys).tobytes())
    if again or programs.last_rollout[0] != seen:
        programs.last_rollout = (seen, programs.rollout(steps, batch)(keys, arena.default_params()))
    return programs.last_rollout[1]


def check_jit_consistency(arena: Arena, key: jax.Array, steps: int = 2) -> None:
    params = _perturbed(arena.default_params(), 1.0)  # the default values, typed as check_no_retrace's params
    programs = _programs(arena)
    s_eager, i_eager = arena.reset(key, params)
    s_jit, i_jit = programs.reset(key, params)
    _assert_trees_close(i_eager, i_jit, f"{arena.name}: jit and non-jit reset disagree")
    for t in range(steps):
        action = arena.sample_action(jax.random.fold_in(key, t))
        s_eager, i_eager = arena.step(s_eager, action, params)
        s_jit, i_jit = programs.step(s_jit, action, params)
        _assert_trees_close(i_eager, i_jit, f"{arena.name}: jit and non-jit step {t} disagree")


def check_no_retrace(arena: Arena, key: jax.Array) -> None:
    """The jitted reset and step (shared with check_jit_consistency, which calls them on the same types) are
    traced once in all, over three params, each with a new key and two steps of new states and actions."""
    programs = _programs(arena)
    for i, factor in enumerate([1.0, 1.01, 0.99]):
        params = _perturbed(arena.default_params(), factor)
        state, _ = programs.reset(jax.random.fold_in(key, i), params)
        for t in range(2):
            state, _ = programs.step(state, arena.sample_action(jax.random.fold_in(key, 100 * i + t)), params)
    if max(programs.traces.values()) > 1:
        raise AssertionError(f"{arena.name}: reset or step retraced on new keys, states, actions or params: "
                             f"traced {programs.traces} times")


def check_vmap(arena: Arena, key: jax.Array, batch: int = 3) -> None:
    """Over keys with shared params, the batched rollout (``vmap`` of reset, and of step inside auto-reset);
    over params, ``jit(vmap(reset))`` and ``jit(vmap(step))``. Every leaf gets the batch axis (and in the
    rollout a time axis) in front of its unbatched shape."""
    params = arena.default_params()
    keys = jax.random.split(key, batch)
    _, single = arena.reset_shapes  # the unbatched structure and shapes
    steps = _rollout_steps(arena)
    infos, stepped, _ = _rollout(arena, key, steps, batch)
    chex.assert_trees_all_equal_structs(single, infos)
    for leaf, one in zip(jax.tree_util.tree_leaves(infos), jax.tree_util.tree_leaves(single), strict=True):
        assert leaf.shape == (batch,) + one.shape, f"{arena.name}: vmapped reset leaf shape {leaf.shape}"
    chex.assert_trees_all_equal_structs(single, stepped)
    for leaf, one in zip(jax.tree_util.tree_leaves(stepped), jax.tree_util.tree_leaves(single), strict=True):
        assert leaf.shape == (batch, steps) + one.shape, f"{arena.name}: vmapped step leaf shape {leaf.shape}"
    actions = jax.vmap(arena.sample_action)(keys)

    batched_params = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs),
                                            *[_perturbed(params, 1.0 + 0.01 * i) for i in range(batch)])
    # one key per arena, as batch_reset(..., params_axis=0) gives (a host arena opens one simulator per key)
    states, infos = jax.jit(jax.vmap(arena.reset, in_axes=(0, 0)))(keys, batched_params)
    _, stepped = jax.jit(jax.vmap(arena.step, in_axes=(0, 0, 0)))(states, actions, batched_params)
    for leaf, one in zip(jax.tree_util.tree_leaves(stepped), jax.tree_util.tree_leaves(single), strict=True):
        assert leaf.shape == (batch,) + one.shape, f"{arena.name}: vmap over params gives leaf shape {leaf.shape}"


def check_determinism(arena: Arena, key: jax.Array, steps: int | None = None) -> None:
    """The same keys give bit-identical rollouts of ``steps`` random actions (default: the shared rollout's
    length, at least 50 steps or two whole episodes and a step); different keys give different starts; an
    episode id fixes the start whatever the key."""
    steps = steps or _rollout_steps(arena)
    first = _rollout(arena, key, steps)
    second = _rollout(arena, key, steps, again=True)
    _assert_trees_identical(first, second, f"{arena.name}: same key, different trajectories")
    if all(np.array_equal(x[0], x[1]) for x in _leaves(first[0].observation)):
        raise AssertionError(f"{arena.name}: different keys gave identical initial observations")
    # two separate traces, so that a task reading host state while tracing (a counter, the clock) shows up
    by_id_1, by_id_2 = (jax.jit(lambda k: arena.reset(k, episode=7)[1])(jax.random.key(i)) for i in (1, 2))
    _assert_trees_identical(by_id_1, by_id_2, f"{arena.name}: episode 7 depends on the key, not only its id")


def check_rollout(arena: Arena, key: jax.Array, steps: int | None = None) -> None:
    """Over the shared rollout (default: an episode, at most 400 steps, and at least 50 or two episodes and a
    step) of each of its keys."""
    steps = steps or _rollout_steps(arena)
    initial, infos, actions = _rollout(arena, key, steps)
    chex.assert_trees_all_equal_structs(initial.replace(final=None), infos.replace(final=None))
    # the keys' rollouts one after the other: step t of key t // steps
    infos, actions = jax.tree_util.tree_map(lambda x: x.reshape((x.shape[0] * x.shape[1],) + x.shape[2:]),
                                            (infos, actions))
    # Arena.step zeroes a faulted step's non-finite observation and reward, so a blow-up shows in its fault
    fault = np.asarray(infos.fault)
    if np.any(fault != 0):
        t = int(np.argmax(fault != 0))
        raise AssertionError(f"{arena.name}: step {t % steps} of random valid actions (key {t // steps}) faulted: "
                             f"{describe(fault[t])}")
    for leaf in jax.tree_util.tree_leaves((initial, infos)):
        if jnp.issubdtype(leaf.dtype, jnp.floating) and not np.all(np.isfinite(np.asarray(leaf))):
            raise AssertionError(f"{arena.name}: non-finite values in info over {steps} steps")
    obs_spec, act_spec = arena.observation_spec, arena.action_spec
    act_spec.validate(jax.tree_util.tree_map(lambda x: x[0], actions), "sampled action")
    if not bool(jnp.all(jax.vmap(obs_spec.contains)(initial.observation))):
        raise AssertionError(f"{arena.name}: initial observation outside {obs_spec}")
    inside = jax.vmap(obs_spec.contains)(infos.observation)
    if not bool(jnp.all(inside)):
        t = int(np.argmin(np.asarray(inside)))
        bad = jax.tree_util.tree_map(lambda x: x[t], infos.observation)
        raise AssertionError(f"{arena.name}: observation at step {t % steps} (key {t // steps}) outside its spec "
                             f"{obs_spec}: {bad}")
    terminal_inside = jax.vmap(obs_spec.contains)(infos.final.observation)
    if not bool(jnp.all(jnp.where(infos.done, terminal_inside, True))):
        raise AssertionError(f"{arena.name}: a terminal observation is outside its spec {obs_spec}")
    if not bool(jnp.all(jax.vmap(act_spec.contains)(actions))):
        raise AssertionError(f"{arena.name}: sampled actions outside the action spec {act_spec}")


CHECKS = (check_jit_consistency, check_no_retrace, check_vmap, check_determinism, check_rollout)


def check_arena(arena: Arena, key: jax.Array | None = None) -> None:
    """Runs every contract check on ``arena`` (they share its compiled programs); raises one ``AssertionError``
    that names each check that failed and why."""
    key = jax.random.key(0) if key is None else key
    failed = []
    for check in CHECKS:
        try:
            check(arena, key)
        except AssertionError as e:
            failed.append(f"{check.__name__}: {e}")
    if failed:
        raise AssertionError("\n".join(failed))
