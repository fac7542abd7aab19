"""A tiny test arena whose physics records the controls it receives (for exact tool tests)."""

import jax.numpy as jnp
from flax import struct

import jarena
from jarena.core.spec import Box, Dict


@struct.dataclass
class Physics:
    last: jnp.ndarray  # last control applied, (2,)
    total: jnp.ndarray  # sum of controls, (2,)
    count: jnp.ndarray  # low-level steps taken


def make(tool=None, task=None, control=None) -> jarena.Arena:
    control = control or Box(-2.0, 2.0, (2,))

    def init(key, params):
        return Physics(jnp.zeros(2), jnp.zeros(2), jnp.zeros((), jnp.int32))

    def step(p, u, params):
        u = jnp.asarray(u, jnp.float32) * jnp.ones(2)
        return Physics(u, p.total + u, p.count + 1)

    def reward_task():
        def update(state, outcome, transition, params):
            # reward = the step's index, so sums over repeats are distinguishable
            return outcome.replace(reward=outcome.reward + transition.physics.count.astype(jnp.float32),
                                   terminated=transition.physics.count >= 5), state
        return jarena.Task(update=update, name="count")

    dynamics = jarena.Dynamics(init=init, step=step, control_spec=control, name="recorder")
    sensor = jarena.Sensor(observe=lambda p, params: {"last": p.last, "total": p.total},
                           spec=Dict(last=Box(-1e9, 1e9, (2,)), total=Box(-1e9, 1e9, (2,))))
    kwargs = {} if tool is None else {"tool": tool}
    return jarena.Arena(dynamics=dynamics, sensor=sensor, task=task or reward_task(), name="recorder", **kwargs)
