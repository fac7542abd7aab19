import jax

import jarena
import jarena_agents


def test_point_mass_oracle_reaches_the_goal():
    arena = jarena.build_arena("classic|domain:point_mass")
    oracle = jarena.evaluate(jarena_agents.build_agent("oracle_point_mass"), arena, jax.random.key(0))
    assert oracle.summary()["success_rate"] >= 0.95
    assert oracle.summary()["distance_mean"] < 0.05
    no_op = jarena.evaluate(jarena_agents.build_agent("no_op"), arena, jax.random.key(0))
    assert oracle.summary()["return_mean"] > no_op.summary()["return_mean"] + 100
    assert no_op.summary()["success_rate"] < 0.1
