"""Brax's environments as arenas: the same observations, rewards and ``done`` as Brax's own env.

The reference is Brax itself: ``brax.envs.get_environment(name, backend=..., **options)`` reset with the
arena's dynamics key and stepped with the same actions. Stepping is compared on two setups that compile
fast on CPU (ant on spring, with options and contacts; inverted_pendulum on MJX, the benchmark's backend,
with action and task transforms in a batch); the other envs are built and their specs checked by tracing.
"""

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.building.grammar import ArenaStringError
from jarena.core import episodes as episodes_lib
from jarena.core.spec import Box

STEPS = 20

#: (observation size, action size) of each env, from Brax's env docstrings ("### Observation Space").
SIZES = {"ant": (27, 8), "halfcheetah": (17, 6), "hopper": (11, 3), "humanoid": (244, 17), "walker2d": (17, 6),
         "reacher": (11, 2), "pusher": (23, 7), "inverted_pendulum": (4, 1), "inverted_double_pendulum": (8, 1)}


def _brax_rollout(name, **options):
    """Brax's env, jitted: ``(raw key, actions (T, A)) -> (reset state, stacked states of T steps)``."""
    from brax import envs
    env = envs.get_environment(name, **options)

    @jax.jit
    def rollout(key, actions):
        state = env.reset(key)
        return state, jax.lax.scan(lambda s, a: (env.step(s, a),) * 2, state, actions)[1]
    return rollout


def _arena_rollout(arena):
    @jax.jit
    def rollout(key, params, actions):
        state, info = arena.reset(key, params)
        return state, info, jax.lax.scan(lambda s, a: arena.step(s, a, params), state, actions)[1]
    return rollout


def _assert_equal(ours, theirs, what):
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    assert ours.shape == theirs.shape and np.array_equal(ours, theirs), (
        f"{what} differs from Brax's: max |diff| {np.max(np.abs(ours.astype(float) - theirs))}")


def test_steps_match_brax_exactly():
    """Ant on spring (contacts, metrics, options that make it terminate) step for step against Brax's env."""
    arena = jarena.build_arena("brax|env:ant(ctrl_cost_weight=0.25,healthy_z_range=[0.2,0.7]),backend:spring")
    assert arena.max_episode_steps == 1000 and arena.name == "brax-ant-spring"
    assert arena.action_spec == Box(-1.0, 1.0, (8,))
    key = jax.random.key(7)
    actions = jax.random.uniform(jax.random.key(1), (STEPS, 8), minval=-1, maxval=1)
    params = arena.default_params()
    rollout = _arena_rollout(arena)
    state, info, infos = rollout(key, params, actions)
    brax_key = jax.random.key_data(episodes_lib.piece_key(state.episode, 0))  # the arena's dynamics key
    first, brax_states = _brax_rollout("ant", backend="spring", ctrl_cost_weight=0.25, healthy_z_range=(0.2, 0.7))(
        brax_key, actions)

    _assert_equal(info.observation["state"], first.obs, "reset observation")
    assert info.observation["state"].shape == (27,)
    _assert_equal(infos.observation["state"], brax_states.obs, "observations")
    _assert_equal(infos.reward, brax_states.reward, "rewards")
    _assert_equal(infos.terminated, brax_states.done > 0, "terminated (Brax's done)")
    assert not infos.truncated.any()
    assert set(infos.metrics) == set(brax_states.metrics)
    for metric, values in brax_states.metrics.items():
        _assert_equal(infos.metrics[metric], values, f"metric {metric}")
    # The options reached Brax: a tight healthy range ends the episode, the control cost has the new weight.
    assert infos.terminated.any() and not infos.terminated[0]
    np.testing.assert_allclose(infos.metrics["reward_ctrl"], -0.25 * jnp.sum(actions ** 2, axis=1), rtol=1e-6)

    # Domain randomisation on the same program: slippery ground changes the trajectory (masses would not:
    # Brax's ant sets spring_mass_scale=1, so spring and positional ignore its masses).
    slippery = params.replace(dynamics=params.dynamics.replace(friction_scale=jnp.float32(0.1)))
    _, _, changed = rollout(key, slippery, actions)
    assert not np.allclose(changed.observation["state"], infos.observation["state"], atol=1e-3)


def test_tools_and_tasks_compose_in_batches():
    """Inverted pendulum on MJX (the benchmark's backend) with ``repeat(2)``, ``reward_scale(0.1)`` and
    ``time_limit:10`` through ``batch_step``: Brax stepped twice per action, rewards summed and scaled,
    truncated after 5 agent steps, then auto-reset. The batch's second arena, on the same episode and
    actions, has a 3x heavier pendulum (batched params)."""
    arena = jarena.build_arena("brax|env:inverted_pendulum,backend:mjx,action:repeat(2),time_limit:10,"
                               "wrap:reward_scale(0.1)")
    assert arena.max_episode_steps == 5
    params = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), arena.default_params())
    params = params.replace(dynamics=params.dynamics.replace(mass_scale=jnp.array([1.0, 3.0], jnp.float32)))
    actions = 0.05 * jax.random.uniform(jax.random.key(2), (6, 1), minval=-1, maxval=1)
    episode = 12345

    @jax.jit
    def run():
        states, info = jarena.batch_reset(arena, None, 2, params, params_axis=0, episodes=jnp.full((2,), episode))
        step = lambda s, a: jarena.batch_step(arena, s, jnp.stack([a, a]), params, params_axis=0)
        return info, jax.lax.scan(step, states, actions)[1]

    info, infos = run()
    brax_key = jax.random.key_data(episodes_lib.piece_key(episode, 0))
    first, brax_states = _brax_rollout("inverted_pendulum", backend="mjx")(brax_key, jnp.repeat(actions[:5], 2, 0))

    _assert_equal(info.observation["state"][0], first.obs, "reset observation")
    assert not (brax_states.done > 0).any(), "small actions keep the pendulum up for 10 Brax steps"
    _assert_equal(infos.final.observation["state"][:5, 0], brax_states.obs[1::2], "observations")
    np.testing.assert_allclose(infos.reward[:5, 0], 0.1 * brax_states.reward.reshape(5, 2).sum(1), rtol=1e-6)
    np.testing.assert_array_equal(infos.truncated[:, 0], [False] * 4 + [True, False])
    np.testing.assert_array_equal(infos.step[:, 0], [1, 2, 3, 4, 0, 1])  # auto-reset after the time limit
    assert not infos.terminated.any()
    _assert_equal(info.observation["state"][1], info.observation["state"][0], "same episode's reset")
    assert not np.allclose(infos.final.observation["state"][:5, 1], infos.final.observation["state"][:5, 0],
                           atol=1e-4)


@pytest.mark.parametrize("name", sorted(SIZES))
def test_every_env_builds_with_brax_specs(name):
    arena = jarena.build_arena(f"brax|env:{name}")
    assert arena.action_spec == Box(-1.0, 1.0, (SIZES[name][1],))
    assert arena.observation_spec["state"].shape == (SIZES[name][0],)  # traces reset, compiles nothing
    assert arena.observation_spec["state"].dtype == np.float32
    assert arena.max_episode_steps == 1000
    assert f"brax|env:{name}" in jarena.list_arenas("benchmark")


def test_state_types_do_not_change_across_steps():
    """Brax's inverted_pendulum returns ``info["time_out"]`` weakly typed after ``step`` (not after ``reset``);
    the arena's state keeps one type, so jitted loops neither retrace nor reject the scan carry."""
    arena = jarena.build_arena("brax|env:inverted_pendulum")
    state, _ = jax.eval_shape(lambda: arena.reset(jax.random.key(0)))
    after, _ = jax.eval_shape(lambda s: arena.step(s, arena.no_op()), state)
    types = lambda tree: [(x.shape, x.dtype, x.weak_type) for x in jax.tree_util.tree_leaves(tree)]
    assert jax.tree_util.tree_structure(after) == jax.tree_util.tree_structure(state)
    assert types(after) == types(state)


def test_options_reach_the_env():
    arena = jarena.build_arena("brax|env:ant(exclude_current_positions_from_observation=false)")
    assert arena.observation_spec["state"].shape == (29,)  # x and y of the torso added


@pytest.mark.parametrize("string,message", [
    ("brax|env:antt", "unknown brax env 'antt' (did you mean 'ant'?); valid choices: ant, halfcheetah"),
    ("brax|env:ant,backend:warp", "unknown backend for brax env 'ant': 'warp'; valid choices: generalized, "
                                  "positional, spring, mjx"),
    ("brax|env:ant(ctrl_cost=0.1)", "unknown option of brax env 'ant': 'ctrl_cost' (did you mean "
                                    "'ctrl_cost_weight'?); valid choices: ctrl_cost_weight, use_contact_forces"),
    ("brax|env:reacher(backend=mjx)", "valid choices: n_frames; give the backend as its own key"),
    ("brax|env:ant(0.1)", "must be given by keyword"),
    ("brax|env:ant(use_contact_forces=true)", "rejects options"),
    ("brax|env:ant,action:repeat(0)", "repeat needs times >= 1"),
])
def test_bad_strings_are_clear_errors(string, message):
    with pytest.raises(ArenaStringError) as e:
        jarena.build_arena(string)
    assert message in str(e.value)


def test_params_scale_both_copies_of_the_model():
    from jarena.arenas.brax.env import BraxParams, apply_params, make_env
    sys_ = make_env("brax.envs.inverted_pendulum:InvertedPendulum", "generalized").sys
    scaled = apply_params(sys_, BraxParams(mass_scale=2.0, friction_scale=0.5))
    np.testing.assert_allclose(scaled.link.inertia.mass, 2 * sys_.link.inertia.mass)
    np.testing.assert_allclose(scaled.link.inertia.i, 2 * sys_.link.inertia.i)
    np.testing.assert_allclose(scaled.body_mass, 2 * sys_.body_mass)
    np.testing.assert_allclose(scaled.body_inertia, 2 * sys_.body_inertia)
    np.testing.assert_allclose(scaled.geom_friction, 0.5 * sys_.geom_friction)


def test_listing_arenas_does_not_import_brax():
    code = ("import sys, jarena; names = jarena.list_arenas('brax'); assert len(names) == 9, names; "
            "assert 'brax' not in sys.modules and 'mujoco' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
