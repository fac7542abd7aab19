import jax
import jax.numpy as jnp
import numpy as np

import jarena
from jarena.arenas.dmc import cheetah
from jarena.core import episodes
from tests.arenas.dmc.reference import assert_suite_episodes, compare, compare_resets, dm_env, perturb, resets


def running(rng, physics):
    """Forward velocities over the whole reward ramp (0 to 10 m/s) and beyond."""
    perturb(rng, physics, 0.1)
    physics.named.data.qvel["rootx"] = rng.uniform(-2, 15)


def test_observation_and_reward_match_dm_control():
    compare("cheetah", "run")
    compare("cheetah", "run", state=running)


def test_initial_states_settle_as_in_the_suite():
    """Random limited joints then 200 settling physics steps: the same states as dm_control's for the same draws."""
    arena = jarena.build_arena("dmc|domain:cheetah,task:run")
    n = 4
    states, infos = resets(arena, n)
    qpos, qvel = np.asarray(states.physics.qpos), np.asarray(states.physics.qvel)
    np.testing.assert_array_equal(states.physics.time, 0)
    env = dm_env("cheetah", "run", 0)
    physics = env.physics
    for i in range(n):
        # the key Arena.reset gives the chain's first task (cheetah run) in episode i
        adr, draws = cheetah.draw_limited_joints(jax.random.fold_in(episodes.piece_key(jnp.int32(i), 4), 0))
        low, high = physics.model.jnt_range[adr].T
        assert np.all((low <= draws) & (draws <= high))
        with physics.reset_context():
            physics.data.qpos[adr] = np.asarray(draws)
            physics.step(nstep=200)
        np.testing.assert_allclose(qpos[i], physics.data.qpos, atol=1e-4)
        np.testing.assert_allclose(qvel[i], physics.data.qvel, atol=1e-3)
        assert np.abs(draws - qpos[i, adr]).max() > 0.01  # the settling steps moved the joints
    compare_resets(arena, "cheetah", "run", states, infos)
    assert_suite_episodes(arena, "cheetah", "run")
