import jax
import jax.numpy as jnp
import pytest

import jarena
from jarena.tasks import goal_reaching, reward_scale, success_bonus, time_limit


def cartpole(**pieces):
    base = jarena.build_arena("classic|domain:cartpole,task:balance,time_limit:1000")
    return base if not pieces else jarena.Arena(**{**dict(dynamics=base.dynamics, sensor=base.sensor,
                                                          task=base.task, tool=base.tool), **pieces})


def rollout(arena, steps, action=0, params=None):
    state, info = arena.reset(jax.random.key(0), params)
    step = jax.jit(arena.step)
    infos = []
    for _ in range(steps):
        state, info = step(state, jnp.asarray(action), params if params is not None else arena.default_params())
        infos.append(info)
    return infos


def test_time_limit_truncates_at_exactly_max_steps():
    base = cartpole()
    arena = cartpole(task=jarena.chain(base.task, time_limit(7)))
    infos = rollout(arena, 8, action=jnp.int32(0))
    # alternate actions would keep the pole up; here check the count directly on a balanced pole
    assert [bool(i.truncated) for i in infos[:6]] == [False] * 6
    assert bool(infos[6].truncated)
    assert arena.max_episode_steps == 7


def test_time_limit_param_is_vmappable():
    base = cartpole()
    arena = cartpole(task=jarena.chain(base.task, time_limit(10)))
    params = arena.default_params()
    params = params.replace(task=(params.task[0], jnp.asarray(3, jnp.int32)))  # (base chain, time_limit)
    infos = rollout(arena, 3, params=params)
    assert bool(infos[2].truncated) and not bool(infos[1].truncated)


def test_reward_scale_and_success_bonus_compose_in_order():
    base = cartpole()
    arena = cartpole(task=jarena.chain(base.task, reward_scale(0.5), success_bonus(2.0)))
    info = rollout(arena, 1)[0]
    assert float(info.reward) == pytest.approx(0.5 + 2.0)  # pole still up: success
    assert float(info.reward_terms["success_bonus"]) == 2.0
    arena = cartpole(task=jarena.chain(base.task, success_bonus(2.0), reward_scale(0.5)))
    assert float(rollout(arena, 1)[0].reward) == pytest.approx(1.5)


def test_success_bonus_can_terminate():
    base = cartpole()
    arena = cartpole(task=jarena.chain(base.task, success_bonus(1.0, terminate=True)))
    assert bool(rollout(arena, 1)[0].terminated)


def test_goal_reaching_on_cartpole_dynamics():
    """One task on another dynamics: reach a cart position sampled per episode."""
    base = cartpole()
    task = jarena.chain(goal_reaching(lambda p: jnp.stack([p.x]), low=[0.5], high=[1.0], threshold=0.1),
                        time_limit(100))
    arena = cartpole(task=task)
    _, info0 = arena.reset(None, episode=0)
    _, info1 = arena.reset(None, episode=1)
    assert info0.goal.shape == (1,) and 0.5 <= float(info0.goal[0]) <= 1.0
    assert float(info0.goal[0]) != float(info1.goal[0])
    infos = rollout(arena, 3, action=1)
    for info in infos:
        assert float(info.reward) == pytest.approx(-float(info.metrics["distance"]))
        assert float(info.metrics["distance"]) == pytest.approx(abs(float(info.observation["state"][0] - info.goal[0])),
                                                                abs=1e-6)
    assert base.goal_dim == 0 and arena.goal_dim == 1


def test_goal_reaching_rejects_bad_arguments():
    with pytest.raises(ValueError, match="reward must be one of"):
        goal_reaching(lambda p: p, [0], [1], reward="shaped")
    with pytest.raises(ValueError, match="differ in shape"):
        goal_reaching(lambda p: p, [0, 0], [1])
    with pytest.raises(ValueError, match="max_steps >= 1"):
        time_limit(0)


def test_chain_rejects_mixed_kinds():
    with pytest.raises(TypeError, match="one kind"):
        jarena.chain(time_limit(3), jarena.tools.repeat(2))
    with pytest.raises(ValueError):
        jarena.chain()


def test_task_initialize_places_the_initial_state_and_chains_in_order():
    import dataclasses
    arena = jarena.build_arena("classic|domain:cartpole")
    base = arena.task

    def start_tilted(key, physics, dynamics_params, params):
        return physics.replace(theta=physics.theta + 0.1)

    def then_double(key, physics, dynamics_params, params):
        return physics.replace(theta=physics.theta * 2.0, x=jax.random.uniform(key, ()))

    tilted = dataclasses.replace(arena, task=jarena.chain(base, jarena.Task(update=lambda s, o, t, p: (o, s),
                                                                             initialize=start_tilted),
                                                          jarena.Task(update=lambda s, o, t, p: (o, s),
                                                                      initialize=then_double)))
    plain, _ = arena.reset(episode=3)
    state, info = tilted.reset(episode=3)
    assert jnp.allclose(state.physics.theta, (plain.physics.theta + 0.1) * 2.0)
    assert info.observation["state"][2] == state.physics.theta  # observation sees the placed state
    again, _ = jax.jit(lambda: tilted.reset(episode=3))()
    assert again.physics.x == state.physics.x  # the initialize key is a function of the episode id
