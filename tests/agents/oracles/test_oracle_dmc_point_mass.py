"""``oracle_dmc_point_mass``: the actuation from the model by hand, then MJX episodes (return over all
100 eval episodes in ``configs/oracle_dmc_point_mass``)."""

import numpy as np
import pytest

from jarena.arenas.dmc import common
from jarena_agents.oracles import dmc_point_mass

EASY = "dmc|domain:point_mass,task:easy"


def test_actuation_read_from_the_model():
    actuation = dmc_point_mass.actuation_of(common.load_model("point_mass"))
    np.testing.assert_allclose(actuation.forces, 0.1 * np.eye(2))  # gear 0.1 on tendons t1 = x, t2 = y
    np.testing.assert_allclose(actuation.jacobian, [[1, 0], [0, 1], [0, 0]])
    g_p, g_d = dmc_point_mass.feedback_gains(actuation, dmc_point_mass.DmcPointMassOracleConfig(k_p=5.0, k_d=0.3))
    # 1 cm short in x: 0.05 N wanted, half of the x actuator's 0.1 N; 0.1 m/s in y: 0.03 N of damping
    np.testing.assert_allclose(g_p @ [0.01, 0.0, 0.0], [0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(g_d @ [0.0, 0.1], [0.0, 0.3], atol=1e-12)


@pytest.fixture(scope="module")
def easy(evaluate_first_episodes):
    return evaluate_first_episodes("oracle_dmc_point_mass", EASY), evaluate_first_episodes("no_op", EASY)


def test_reaches_the_target(easy):
    oracle, no_op = easy
    assert oracle.returns.min() > 800  # ~100 steps of approach at the 0.1 m/s the actuators allow
    assert np.all(oracle.successes)
    assert no_op.returns.max() < 50
