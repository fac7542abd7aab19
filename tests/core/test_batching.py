import jax
import jax.numpy as jnp
import numpy as np

import jarena


def test_batch_reset_shapes_and_episodes():
    arena = jarena.build_arena("classic|domain:cartpole")
    states, infos = jarena.batch_reset(arena, jax.random.key(0), 5)
    assert infos.observation["state"].shape == (5, 4)
    assert len(set(np.asarray(infos.episode).tolist())) == 5
    _, infos = jarena.batch_reset(arena, None, 3, episodes=jnp.arange(3))
    np.testing.assert_array_equal(infos.episode, [0, 1, 2])


def test_auto_reset_keeps_terminal_observation_and_starts_fresh_episodes():
    arena = jarena.build_arena("classic|domain:cartpole")
    step = jax.jit(lambda s, a: jarena.auto_reset(arena, s, a))
    plain_step = jax.jit(arena.step)
    state, info = arena.reset(jax.random.key(0))
    starts, boundaries = [np.asarray(info.observation["state"])], 0
    for _ in range(200):
        expected_state, expected = plain_step(state, jnp.int32(1))  # always push right: falls fast
        state, info = step(state, jnp.int32(1))
        np.testing.assert_array_equal(info.final.observation["state"], expected.observation["state"])
        assert float(info.reward) == float(expected.reward)
        if bool(info.done):
            boundaries += 1
            assert bool(info.terminated)
            assert int(info.final.episode) == int(expected.episode) != int(info.episode)
            assert int(info.step) == 0 and int(info.final.step) == int(expected.step)
            starts.append(np.asarray(info.observation["state"]))
        else:
            np.testing.assert_array_equal(info.observation["state"], expected.observation["state"])
    assert boundaries >= 5
    # every new episode has fresh randomness: no two initial states are equal
    assert len({s.tobytes() for s in starts}) == len(starts)


def test_batch_step_with_and_without_reset():
    arena = jarena.build_arena("classic|domain:cartpole")
    states, infos = jarena.batch_reset(arena, jax.random.key(0), 4)
    actions = jnp.ones(4, jnp.int32)
    for _ in range(30):
        states, infos = jarena.batch_step(arena, states, actions, reset_done=False)
    assert bool(jnp.all(infos.step == 30))
    states, infos = jarena.batch_reset(arena, jax.random.key(0), 4)
    for _ in range(30):
        states, infos = jarena.batch_step(arena, states, actions)
    assert bool(jnp.all(infos.step < 30))


def test_auto_reset_episode_ids_do_not_repeat_or_lock_step():
    """Episode ids drawn under auto-reset stay distinct across arenas and time (no short cycles)."""
    arena = jarena.build_arena("classic|domain:cartpole,time_limit:1")  # every step ends an episode
    states, infos = jarena.batch_reset(arena, jax.random.key(0), 64)
    step = jax.jit(lambda s: jarena.batch_step(arena, s, jnp.zeros(64, jnp.int32)))
    seen = set(np.asarray(infos.episode).tolist())
    for _ in range(50):
        states, infos = step(states)
        seen |= set(np.asarray(infos.episode).tolist())
    assert len(seen) == 64 * 51


def test_lazy_reset_gives_the_same_batch_as_select_reset():
    import dataclasses

    import numpy as np
    arena = jarena.build_arena("classic|domain:cartpole,time_limit:20")
    lazy = dataclasses.replace(arena, auto_reset="lazy")

    def rollout(a):
        def body(carry, key):
            states = carry
            actions = jax.random.randint(key, (6,), 0, 2)
            states, info = jarena.batch_step(a, states, actions)
            return states, (info.observation["state"], info.done, info.episode, info.final.observation["state"])
        states, _ = jarena.batch_reset(a, jax.random.key(0), 6)
        return jax.lax.scan(body, states, jax.random.split(jax.random.key(1), 60))[1]

    eager_out, lazy_out = jax.jit(lambda: rollout(arena))(), jax.jit(lambda: rollout(lazy))()
    assert eager_out[1].any() and not eager_out[1].all()  # some steps restart episodes, some do not
    for e, z in zip(eager_out, lazy_out, strict=True):
        np.testing.assert_array_equal(e, z)


def test_lazy_reset_computes_resets_only_in_steps_where_an_arena_finished():
    """The lazy path must skip the reset computation, not merely give the same batch: a task whose reset
    reports each (batched) execution runs 1 + 60 times eagerly, 1 + (steps with a finished arena) lazily,
    and once (the first reset) when arenas repeat their first episode."""
    import dataclasses

    from jarena.core.task import Task

    executions = []

    def reset(key, physics, outcome, params):
        jax.debug.callback(lambda: executions.append(1))
        return outcome, ()

    counter = Task(update=lambda state, outcome, transition, params: (outcome, state), reset=reset,
                   name="count_resets")
    base = jarena.build_arena("classic|domain:cartpole,time_limit:20")
    counts = {}
    for strategy in ("select", "lazy", "repeat"):
        arena = dataclasses.replace(base, task=Task.chain(base.task, counter), auto_reset=strategy)

        def rollout(arena=arena):
            def body(states, key):
                states, info = jarena.batch_step(arena, states, jax.random.randint(key, (6,), 0, 2))
                return states, info.done.any()
            states, _ = jarena.batch_reset(arena, jax.random.key(0), 6)
            return jax.lax.scan(body, states, jax.random.split(jax.random.key(1), 60))[1]

        executions.clear()
        any_done = jax.block_until_ready(jax.jit(rollout)())
        counts[strategy] = (len(executions), int(any_done.sum()))
    assert counts["select"][0] == 1 + 60
    assert 0 < counts["lazy"][1] < 60 and counts["lazy"][0] == 1 + counts["lazy"][1]
    assert counts["repeat"][0] == 1 and counts["repeat"][1] > 0


def test_repeat_reset_replays_each_arenas_first_episode():
    """``auto_reset:repeat`` (Brax's and Playground's auto-reset): a finished arena restarts from the
    initial state its first episode had, with that episode's id; the finished step's transition is kept."""
    arena = jarena.build_arena("classic|domain:cartpole,time_limit:7,auto_reset:repeat")
    assert arena.auto_reset == "repeat"
    states, first = jarena.batch_reset(arena, jax.random.key(0), 4)
    step = jax.jit(lambda s, a: jarena.batch_step(arena, s, a))
    plain = jax.jit(lambda s, a: jarena.batch_step(arena, s, a, reset_done=False))
    restarts = 0
    for t in range(30):
        actions = jnp.full((4,), t % 2, jnp.int32)
        _, expected = plain(states, actions)
        states, info = step(states, actions)
        np.testing.assert_array_equal(info.final.observation["state"], expected.observation["state"])
        np.testing.assert_array_equal(info.reward, expected.reward)
        done = np.asarray(info.done)
        restarts += done.sum()
        np.testing.assert_array_equal(info.observation["state"][done], first.observation["state"][done])
        np.testing.assert_array_equal(info.episode, first.episode)
        for now, start in zip(jax.tree_util.tree_leaves(states.physics),
                              jax.tree_util.tree_leaves(states.start[0].physics), strict=True):
            np.testing.assert_array_equal(now[done], start[done])
    assert restarts >= 4 * 4  # time limit 7: four restarts per arena in 30 steps
    one_state, one_info = arena.reset(jax.random.key(1))  # the single-arena path stores its start too
    for _ in range(7):
        one_state, one_info = jarena.auto_reset(arena, one_state, jnp.int32(0))
    assert bool(one_info.done) and int(one_info.step) == 0


def test_unknown_or_mismatched_reset_strategies_are_clear_errors():
    import dataclasses

    import pytest

    with pytest.raises(jarena.ArenaStringError, match="unknown auto_reset 'again'.*select, lazy, repeat"):
        jarena.build_arena("classic|domain:cartpole,auto_reset:again")
    arena = jarena.build_arena("classic|domain:cartpole")
    with pytest.raises(ValueError, match="unknown auto_reset 'agian'; choose from select, lazy, repeat"):
        dataclasses.replace(arena, auto_reset="agian")
    state, _ = arena.reset(jax.random.key(0))  # made by a "select" arena: no stored start
    with pytest.raises(ValueError, match="auto_reset 'repeat' but its state holds no first episode"):
        jarena.auto_reset(dataclasses.replace(arena, auto_reset="repeat"), state, jnp.int32(0))
