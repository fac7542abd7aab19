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
    lazy = dataclasses.replace(arena, lazy_reset=True)

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
    reports each (batched) execution runs 1 + 60 times eagerly, and 1 + (steps with a finished arena) lazily."""
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
    for lazy in (False, True):
        arena = dataclasses.replace(base, task=Task.chain(base.task, counter), lazy_reset=lazy)

        def rollout(arena=arena):
            def body(states, key):
                states, info = jarena.batch_step(arena, states, jax.random.randint(key, (6,), 0, 2))
                return states, info.done.any()
            states, _ = jarena.batch_reset(arena, jax.random.key(0), 6)
            return jax.lax.scan(body, states, jax.random.split(jax.random.key(1), 60))[1]

        executions.clear()
        any_done = jax.block_until_ready(jax.jit(rollout)())
        counts[lazy] = (len(executions), int(any_done.sum()))
    assert counts[False][0] == 1 + 60
    assert 0 < counts[True][1] < 60 and counts[True][0] == 1 + counts[True][1]
