"""The cloth flattening oracle: the same actions in any batch; its lookahead takes the pull that covers most."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena_agents.registry import build_agent
from tests.arenas.cloth.episodes import Episodes

# the rows ``index`` (an int array) of every leaf: one compiled gather per tree and index shape, not one eager op
# per leaf
_take = jax.jit(lambda tree, index: jax.tree_util.tree_map(lambda x: x[index], tree))


def _score_of(taken, tried, scores):
    """The score (B,) of each of B cloths' ``taken`` action (B, A): that of the proposal among its ``tried`` (B, P, A)
    that it is, whose ``scores`` (B, P) were stepped in the same batch (the proposals' scores are computed as the
    oracle computes them, which XLA compiles once; stepping the taken actions apart would compile the step again)."""
    same = (tried == taken[:, None]).all(-1)
    assert same.any(-1).all(), (taken, tried)  # the taken action is one of the proposals
    return scores[np.arange(len(taken)), same.argmax(-1)]


@pytest.fixture(scope="module")
def nine_crumpled():
    """Nine crumpled 16 x 16 starts of a side-fold arena (the flattening oracle reads only the particles),
    reset once: the info and privileged state the oracles act on. (The oracles' former sums, in jnp.sum's and the
    matmuls' batch-dependent order, fail the test below on these as on 24 x 24 cloths, in the same batches.)"""
    arena = jarena.build_arena("cloth|task:side_fold,initial:crumpled,particles:16,resolution:32,horizon:2")

    @jax.jit
    def reset(episodes):
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(episodes)
        return info, jax.vmap(arena.privileged)(state)

    return arena, *reset(jnp.arange(9))


@pytest.mark.parametrize("name", ["oracle_cloth_flattening", "oracle_cloth_folding"])
def test_the_oracle_acts_the_same_to_the_bit_in_any_batch(name, nine_crumpled):
    # a last-bit difference in an action changes where a crumpled cloth lands, and the episode diverges: the
    # oracles' sums run in a fixed order, unlike matmuls and jnp.sum, whose order follows the batch size
    arena, info, privileged = nine_crumpled
    oracle = build_agent(name, {"lookahead": False})

    @jax.jit
    def first_actions(info, privileged):
        agent_state = oracle.init(jax.random.key(0), arena.spec, info.reward.shape[0])
        return oracle.act(agent_state, info, jax.random.key(1), privileged)[0]

    whole = np.asarray(first_actions(info, privileged))
    for part in (np.array([4]), np.array([2, 7, 0]), np.arange(9)[::-1]):
        np.testing.assert_array_equal(np.asarray(first_actions(_take(info, part), _take(privileged, part))),
                                      whole[part])


LOOKAHEAD_ARENA = "cloth|domain:square_fabric,initial:crumpled,particles:10,resolution:16,horizon:2"


@pytest.fixture(scope="module")
def crumpled():
    """The lookahead arena and its first episodes (of 12: at least the 3 the tests use) whose start covers
    under 0.9 (a small cloth often lands flat), reset once as the evaluation resets them: their ids, the starts'
    normalised coverage, the first 3 as :class:`Episodes` (for the oracles to run) and the info and privileged
    state of the first 2."""
    arena = jarena.build_arena(LOOKAHEAD_ARENA)
    state, info = Episodes(arena, range(12)).start
    start = np.asarray(info.metrics["normalised_coverage"])
    chosen = np.flatnonzero(start < 0.9)
    assert len(chosen) >= 3, start
    three = Episodes(arena, chosen[:3], start=_take((state, info), chosen[:3]))
    privileged = jax.jit(jax.vmap(arena.privileged))(_take(state, chosen[:2]))
    return SimpleNamespace(arena=arena, episodes=chosen, start=start[chosen], three=three,
                           info=_take(info, chosen[:2]), privileged=privileged)


def test_the_lookahead_takes_the_proposal_that_covers_most(crumpled):
    from jarena.arenas.cloth import coverage
    from jarena_agents.oracles import cloth_actions
    from jarena_agents.oracles.cloth_flattening import flat_goal, proposals
    from jarena_agents.planners.model import arena_model

    arena = crumpled.arena
    oracle = build_agent("oracle_cloth_flattening", {"arena": LOOKAHEAD_ARENA})
    model = arena_model(arena)

    @jax.jit
    def check(info, privileged):
        agent_state = oracle.init(jax.random.key(0), arena.spec, info.reward.shape[0])
        taken, _ = oracle.act(agent_state, info, jax.random.key(1), privileged)
        mesh = privileged.physics.mesh
        positions = privileged.physics.positions
        tried = jax.vmap(lambda x: proposals(x, flat_goal(x, mesh, 0.15), mesh, 1, "pixel", 0.25, 4, True))(positions)
        return (jax.vmap(lambda x: coverage.normalised_coverage(x, mesh))(positions), tried, taken,
                cloth_actions.each_score(privileged, tried, lambda start, a: coverage.normalised_coverage(
                    model.step(start, a)[0].physics.positions, mesh)))

    now, actions, action, tried = (np.asarray(x) for x in check(crumpled.info, crumpled.privileged))
    taken = _score_of(action, actions, tried)
    assert tried.shape == (2, 33 + 16 + 4)  # the defaults: 16 edge handles twice, 4 x 4 inner particles, 4 tips
    assert (now < 0.9).all(), now  # the oracle acts (it idles from 0.999)
    for i in range(2):
        assert len(np.unique(tried[i])) > 3, tried[i]  # the proposals differ
        assert taken[i] == tried[i].max(), (taken[i], tried[i])
        assert taken[i] >= tried[i, 0]  # never worse than the analytic pull


def test_the_lookahead_flattens_more_than_the_analytic_pull(crumpled):
    before = crumpled.start[:3]
    results = {}
    for name, config in (("lookahead", {"arena": LOOKAHEAD_ARENA}), ("analytic", {"lookahead": False})):
        # evaluate's loop on the 3 episodes, their reset and step compiled once for both oracles
        oracle = build_agent("oracle_cloth_flattening", config)
        results[name] = np.asarray(crumpled.three.run(oracle).metrics["normalised_coverage"])
    assert results["lookahead"].mean() > before.mean() + 0.2, (before, results)
    assert results["lookahead"].mean() >= results["analytic"].mean(), results


def test_the_lookahead_needs_the_arena_it_simulates():
    from jarena_agents.config import ConfigError

    with pytest.raises(ConfigError, match="arena='<arena string>'.*lookahead=False"):
        build_agent("oracle_cloth_flattening")
    with pytest.raises(ConfigError, match="cannot plan in arena"):
        build_agent("oracle_cloth_flattening", {"arena": "gym|id:CartPole-v1"})


def test_the_fit_residual_is_zero_for_a_flat_cloth_and_grows_with_a_fold():
    from jarena.arenas.cloth.mesh import ClothMesh
    from jarena_agents.oracles.cloth_flattening import fit_residual

    mesh = ClothMesh(rows=10, cols=10, spacing=0.04)
    residual = jax.jit(lambda x: fit_residual(x, mesh))  # one program for both cloths, not a hundred eager ops
    flat = np.asarray(mesh.rest_positions, np.float32)
    angle = 0.7  # any rigid motion in the plane, mirrored too, fits exactly
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    moved = flat @ rotation.T * np.array([1, -1, 1]) + np.array([0.05, -0.02, 0.0])
    assert float(residual(jnp.asarray(moved, jnp.float32))) < 1e-5
    folded = flat.copy()
    right = folded[:, 0] > 0  # the right half laid over the left, a layer up
    folded[right, 0] *= -1
    folded[right, 2] += 0.03
    assert float(residual(jnp.asarray(folded))) > 0.03


def test_interior_proposals_put_inner_particles_at_their_goals_and_the_score_counts_the_residual(crumpled):
    from jarena.arenas.cloth import coverage
    from jarena_agents.oracles import cloth_actions
    from jarena_agents.oracles.cloth_flattening import fit_residual, flat_goal, proposals
    from jarena_agents.planners.model import arena_model

    arena = crumpled.arena
    config = {"arena": LOOKAHEAD_ARENA, "interior": 3, "outward": 0.15, "unfold_weight": 2.0}
    oracle = build_agent("oracle_cloth_flattening", config)
    model = arena_model(arena)

    @jax.jit
    def check(info, privileged):
        taken, _ = oracle.act(oracle.init(jax.random.key(0), arena.spec, info.reward.shape[0]), info,
                              jax.random.key(1), privileged)
        mesh = privileged.physics.mesh

        def score(start, a):
            after = model.step(start, a)[0].physics.positions
            return coverage.normalised_coverage(after, mesh) - 2.0 * fit_residual(after, mesh)

        def one(positions):
            goal = flat_goal(positions, mesh, 0.15)
            tried = proposals(positions, goal, mesh, 1, "pixel", 0.15, 3, True)  # tips on, as the oracle's default
            inner = jnp.asarray(cloth_actions.interior_handles(mesh, 3))
            expected = jax.vmap(lambda p, q: cloth_actions.encode(p[None], q[None], "pixel"))(
                positions[inner, :2], goal[inner])
            return tried, expected

        tried, expected = jax.vmap(one)(privileged.physics.positions)
        return tried, expected, taken, cloth_actions.each_score(privileged, tried, score)

    tried, expected, action, scores = (np.asarray(x) for x in check(crumpled.info, crumpled.privileged))
    taken = _score_of(action, tried, scores)
    assert tried.shape == (2, 33 + 9 + 4, 4)
    np.testing.assert_allclose(tried[:, 33:42], expected, atol=1e-6)  # these 9: inner particles to their goals
    for i in range(2):
        assert taken[i] == scores[i].max(), (taken[i], scores[i])
