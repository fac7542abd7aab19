import jax
import jax.numpy as jnp
import numpy as np
import pytest
from recorder_arena import make

import jarena
from jarena.core.spec import Box, Discrete
from jarena.tools import clip, delay, noise, repeat, rescale, sticky


def steps(arena, actions, key=0):
    state, info = arena.reset(jax.random.key(key))
    step = jax.jit(arena.step)
    out = []
    for a in actions:
        state, info = step(state, jnp.asarray(a, jnp.float32))
        out.append((state, info))
    return out


def test_rescale_maps_unit_box_to_control_bounds():
    arena = make(tool=rescale(-1.0, 1.0))
    assert arena.action_spec == Box(-1.0, 1.0, (2,))
    (state, info), = steps(arena, [[-1.0, 0.5]])
    np.testing.assert_allclose(state.physics.last, [-2.0, 1.0])
    np.testing.assert_allclose(arena.no_op(), [0.0, 0.0])


def test_rescale_needs_bounded_box():
    with pytest.raises(TypeError, match="bounded float Box"):
        _ = make(tool=rescale(), control=Box(-np.inf, np.inf, (2,))).action_spec


def test_clip_bounds_the_control():
    (state, _), = steps(make(tool=clip()), [[5.0, -0.5]])
    np.testing.assert_allclose(state.physics.last, [2.0, -0.5])


def test_repeat_accumulates_rewards_and_steps_physics():
    arena = make(tool=repeat(2))
    (s1, i1), (s2, i2) = steps(arena, [[1.0, 1.0], [0.5, 0.5]])
    assert int(s1.physics.count) == 2 and float(i1.reward) == 1 + 2
    assert int(s2.physics.count) == 4 and float(i2.reward) == 3 + 4
    np.testing.assert_allclose(s2.physics.total, [3.0, 3.0])
    assert int(i2.step) == 2  # agent steps


def test_repeat_stops_at_termination_inside_the_repeat():
    arena = make(tool=repeat(4))  # the task terminates at low-level step 5
    (s1, i1), (s2, i2) = steps(arena, [[1.0, 1.0], [1.0, 1.0]])
    assert not bool(i1.terminated)
    assert bool(i2.terminated)
    assert int(s2.physics.count) == 5  # frozen at the terminating step, not 8
    assert float(i2.reward) == 5.0  # steps 6..8 add nothing


def test_noise_on_box_and_discrete():
    arena = make(tool=noise(0.5))
    (s, _), = steps(arena, [[0.0, 0.0]])
    assert not np.allclose(s.physics.last, 0.0)
    assert np.all(np.abs(np.asarray(s.physics.last)) <= 2.0)
    # Discrete: epsilon-random; with scale 1 actions are uniform over {0, 1, 2}
    arena = make(tool=noise(1.0), control=Discrete(3))
    state, _ = arena.reset(jax.random.key(0))
    step = jax.jit(arena.step)
    seen = set()
    for _ in range(30):
        state, _ = step(state, jnp.int32(0))
        seen.add(int(state.physics.last[0]))
    assert seen == {0, 1, 2}


def test_delay_applies_past_actions():
    arena = make(tool=delay(2))
    out = steps(arena, [[1.0, 1.0], [2.0, 2.0], [-1.0, -1.0], [0.5, 0.5]])
    applied = [float(s.physics.last[0]) for s, _ in out]
    assert applied == [0.0, 0.0, 1.0, 2.0]


def test_sticky_probability_extremes():
    always = steps(make(tool=sticky(1.0)), [[1.0, 1.0], [2.0, 2.0], [-1.0, -1.0]])
    assert [float(s.physics.last[0]) for s, _ in always] == [1.0, 1.0, 1.0]
    never = steps(make(tool=sticky(0.0)), [[1.0, 1.0], [2.0, 2.0]])
    assert [float(s.physics.last[0]) for s, _ in never] == [1.0, 2.0]


def test_chain_order_first_tool_sees_agent_action():
    arena = make(tool=jarena.chain(rescale(-1.0, 1.0), repeat(2)))
    assert arena.action_spec == Box(-1.0, 1.0, (2,)) and arena.tool.substeps == 2
    (s, i), = steps(arena, [[1.0, 1.0]])
    np.testing.assert_allclose(s.physics.total, [4.0, 4.0])


def test_tool_argument_errors():
    with pytest.raises(ValueError):
        repeat(0)
    with pytest.raises(ValueError):
        sticky(1.5)
    with pytest.raises(ValueError):
        rescale(1.0, -1.0)
