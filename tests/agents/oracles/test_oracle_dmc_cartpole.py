"""``oracle_dmc_cartpole``: the pole's physics and the LQR gain from the model, then MJX episodes
(return over all 100 eval episodes in ``configs/oracle_dmc_cartpole``)."""

import jax.numpy as jnp
import numpy as np
import pytest

from jarena.arenas.dmc import common
from jarena_agents.oracles import dmc_cartpole, lqr

SWINGUP = "dmc|domain:cartpole,task:swingup"


def test_pole_physics_read_from_the_model():
    pole = dmc_cartpole.pole_of(common.load_model("cartpole"))
    assert (pole.mass, pole.com, pole.gravity) == pytest.approx((0.1, 0.5, 9.81))
    # a 1 m rod of 0.1 kg about its end: m L^2 / 3 = 0.0333; the capsule's 0.045 m radius adds a little
    assert 0.0333 < pole.inertia < 0.036
    hanging = dmc_cartpole.pole_energy(pole, jnp.pi, 0.0)
    assert float(hanging) == pytest.approx(-2 * 0.1 * 9.81 * 0.5, rel=1e-5)  # -m g 2l: 0.981 J below upright


def test_lqr_gain_stabilises_the_linearised_upright_cartpole():
    model = common.load_model("cartpole")
    a, b = lqr.linearise(model, np.zeros(model.nq))
    assert np.abs(np.linalg.eigvals(a)).max() > 1.0  # upright is unstable
    assert b[2, 0] > 0 > b[3, 0]  # pushing right accelerates the cart right and tips the pole back
    gain = dmc_cartpole.upright_gain(model, dmc_cartpole.DmcCartpoleOracleConfig())
    assert np.abs(np.linalg.eigvals(a - b @ gain)).max() < 1.0


@pytest.fixture(scope="module")
def swingup(evaluate_first_episodes):
    return evaluate_first_episodes("oracle_dmc_cartpole", SWINGUP), evaluate_first_episodes("no_op", SWINGUP)


def test_swings_up_and_balances(swingup):
    oracle, no_op = swingup
    assert oracle.returns.min() > 800  # 859 +- 1 over 100 episodes
    assert np.all(oracle.successes)  # upright (cos >= 0.995) and centred (|x| <= 0.25) at the end
    assert no_op.returns.max() < 10


def test_balances(evaluate_first_episodes):
    # no_op scores ~750 here (the pole falls slowly, then swings back up close to upright)
    oracle = evaluate_first_episodes("oracle_dmc_cartpole", "dmc|domain:cartpole,task:balance")
    assert oracle.returns.min() > 995
    assert np.all(oracle.successes)
