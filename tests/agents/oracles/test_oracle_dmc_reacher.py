"""``oracle_dmc_reacher``: the arm from the model and the inverse kinematics by hand, then MJX episodes
(returns over all 100 eval episodes in ``configs/oracle_dmc_reacher``)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.dmc import reacher
from jarena_agents.oracles import dmc_reacher

EASY = "dmc|domain:reacher,task:easy"


@pytest.fixture(scope="module")
def arm():
    return dmc_reacher.arm_of(reacher.names("easy").model)


def test_arm_read_from_the_model(arm):
    assert (arm.l1, arm.l2) == pytest.approx((0.12, 0.12))
    assert arm.wrist_range == pytest.approx((-np.deg2rad(160), np.deg2rad(160)))
    assert arm.gear == pytest.approx((0.05, 0.05))


def test_inverse_kinematics_by_hand(arm):
    target = jnp.array([0.12, 0.12])  # both links 0.12 m: the elbow at a right angle, on either side
    near_first = dmc_reacher.inverse_kinematics(arm, target, jnp.array([0.1, 1.0]))
    near_second = dmc_reacher.inverse_kinematics(arm, target, jnp.array([1.5, -1.0]))
    np.testing.assert_allclose(near_first, [0.0, np.pi / 2], atol=1e-5)
    np.testing.assert_allclose(near_second, [np.pi / 2, -np.pi / 2], atol=1e-5)
    # travel wraps the shoulder: from q = (3.1, -0.3) the elbow-down solution (-2.51, -1.17) is
    # 0.68 + 0.87 rad away (5.61 + 0.87 unwrapped), the elbow-up one (2.61, 1.17) 0.49 + 1.47 rad
    behind = dmc_reacher.inverse_kinematics(arm, jnp.array([-0.2, -0.01]), jnp.array([3.1, -0.3]))
    np.testing.assert_allclose(behind, [-2.508, -1.168], atol=2e-3)


def test_inverse_kinematics_reaches_every_task_target(arm):
    angles, radii = np.meshgrid(np.linspace(0, 2 * np.pi, 13), [0.05, 0.1, 0.15, 0.199])
    targets = jnp.stack([radii.ravel() * np.sin(angles.ravel()), radii.ravel() * np.cos(angles.ravel())], -1)
    q_now = jax.random.uniform(jax.random.key(0), (targets.shape[0], 2), minval=-2.7, maxval=2.7)
    q = jax.vmap(lambda t, q0: dmc_reacher.inverse_kinematics(arm, t, q0))(targets, q_now)
    reached = jax.vmap(lambda qi: dmc_reacher.forward_kinematics(arm, qi))(q)
    np.testing.assert_allclose(reached, targets, atol=1e-5)
    assert np.all(np.abs(q[:, 1]) <= np.deg2rad(160)) and np.all(np.abs(q[:, 0]) <= np.pi)


@pytest.fixture(scope="module")
def easy(evaluate_first_episodes):
    return evaluate_first_episodes("oracle_dmc_reacher", EASY), evaluate_first_episodes("no_op", EASY)


def test_touches_the_target(easy):
    oracle, no_op = easy
    assert oracle.returns.min() > 950  # at most 50 of the 1000 steps spent reaching
    assert np.all(oracle.successes)  # the finger is on the target at the end
    assert oracle.returns.mean() > no_op.returns.mean() + 500


def test_touches_the_small_target(evaluate_first_episodes):
    oracle = evaluate_first_episodes("oracle_dmc_reacher", "dmc|domain:reacher,task:hard")  # no_op: 0 on all 100
    assert oracle.returns.min() > 950
    assert np.all(oracle.successes)
