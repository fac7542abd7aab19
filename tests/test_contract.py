"""Registered arenas pass the contract checker (jarena.testing).

Every classic arena runs here; of the MuJoCo arenas, whose MJX programs take tens of seconds each to
compile on a 2-core CPU, a representative few. ``JARENA_FULL_CONTRACT=1`` checks every listed arena
(done on the GPU machine; see benchmarks/RESULTS.md).
"""

import os

import jax
import pytest

import jarena
from jarena.testing import check_arena

MUJOCO_SAMPLE = ["dmc|domain:point_mass,task:easy"]
LISTED = jarena.list_arenas() if os.environ.get("JARENA_FULL_CONTRACT") else (
    [a for a in jarena.list_arenas() if a.startswith("classic|")] + MUJOCO_SAMPLE)
ARENAS = LISTED + [
    "classic|domain:cartpole,action:[sticky(0.2),noise(0.1),repeat(2),delay(1)],wrap:[reward_scale(0.5),success_bonus(1)]",
    "classic|domain:pendulum,time_limit:20,action:delay(1),auto_reset:repeat",  # stored first episode + tool state
    # small cloths, a flat start and a crumpled one (~250 chaotic physics steps, compiled as one program whether
    # reset runs eagerly or under jit, so the two start the same cloth)
    "cloth|domain:square_fabric,initial:flat,particles:10,resolution:32,horizon:3",
    "cloth|domain:rectangular_fabric,initial:crumpled,action:pick_and_place(2),particles:12,resolution:32,horizon:2",
    # host arenas (Gymnasium's own envs stepped through host calls), with a jarena tool and transform on top
    "gym|id:CartPole-v1",
    "gym|id:Pendulum-v1(g=9.81),action:repeat(2),time_limit:50,wrap:reward_scale(0.1)",
]


@pytest.mark.parametrize("arena_string", ARENAS)
def test_arena_passes_every_contract_check(arena_string):
    """Every check on one built arena, so that the checks share its compiled reset, step and rollout (the
    MJX and cloth programs compile in tens of seconds each); the failure names every check that failed."""
    arena = jarena.build_arena(arena_string)
    check_arena(arena)


def test_checker_catches_a_broken_arena():
    """A task that reads a global counter (impure) makes the determinism check fail."""
    import itertools

    import jax.numpy as jnp

    base = jarena.build_arena("classic|domain:cartpole")
    counter = itertools.count()

    def reset(key, physics, outcome, params):
        return outcome.replace(goal=jnp.full((1,), float(next(counter)))), ()

    def update(state, outcome, transition, params):
        return outcome.replace(goal=jnp.full((1,), float(next(counter)))), state

    broken = jarena.Arena(dynamics=base.dynamics, sensor=base.sensor,
                          task=jarena.chain(base.task, jarena.Task(update=update, reset=reset)))
    from jarena.testing import check_determinism
    with pytest.raises(AssertionError):
        check_determinism(broken, jax.random.key(0))
    with pytest.raises(AssertionError, match="check_determinism: "):
        check_arena(broken)


def test_jit_consistency_tolerates_one_edge_pixel_in_ten_thousand_and_no_more():
    """Images and maps of 10,000 elements or more may differ at one element in 10,000 (a ray on an edge flips
    under rounding); a second differing element, or any difference in a smaller array, fails."""
    import numpy as np

    from jarena.testing.contract import IMAGE_SIZE, _assert_trees_close

    height = np.zeros((100, 100), np.float32)
    flipped = height.copy()
    flipped[3, 4] = 0.0004
    _assert_trees_close({"height": height}, {"height": flipped}, "one pixel")
    rgb = np.zeros((100, 100, 3), np.uint8)
    changed = rgb.copy()
    changed[5, 6, :] = 9
    _assert_trees_close({"rgb": rgb}, {"rgb": changed}, "three elements in 30,000")
    flipped[50, 50] = 0.0004
    with pytest.raises(AssertionError, match="two pixels"):
        _assert_trees_close({"height": height}, {"height": flipped}, "two pixels")
    small = np.zeros(IMAGE_SIZE - 1, np.float32)
    with pytest.raises(AssertionError, match="small"):
        _assert_trees_close(small, np.where(np.arange(small.size) == 7, 1e-3, small), "small")
