"""The cloth folding oracle: it reads the fold from info.goal, folds flat cloths, leaves spare pickers idle, and its
lookahead takes the fold that ends nearest the goal."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
from jarena.core.agent import AgentArenaMismatch
from jarena_agents.config import ConfigError
from jarena_agents.oracles import cloth_actions
from jarena_agents.oracles.cloth_folding import flat_pose, floor_layer
from jarena_agents.registry import build_agent
from tests.arenas.cloth.episodes import Episodes

ANALYTIC = {"lookahead": False}


def _string(task: str, tool: str = "pixel_pick_and_place(1)", initial: str = "flat", particles: int = 16) -> str:
    return (f"cloth|task:{task},initial:{initial},particles:{particles},resolution:32,horizon:2,action:{tool},"
            "depth:false,mask:false")


def _arena(task: str, tool: str = "pixel_pick_and_place(1)", initial: str = "flat") -> jarena.Arena:
    return jarena.build_arena(_string(task, tool, initial))


@pytest.mark.parametrize("task", ["side_fold", "diagonal_fold", "one_corner_inward"])
def test_the_flat_pose_under_a_goal_is_the_cloth_it_folds(task):
    arena = _arena(task)

    @jax.jit  # one program (op by op, the reset and the poses dispatch hundreds of small ones)
    def poses():
        state, info = arena.reset(episode=3)
        physics = arena.privileged(state).physics
        goal = info.goal.reshape(-1, 3)
        return floor_layer(goal, physics.mesh), flat_pose(goal, physics.mesh), physics.positions[:, :2]

    floor, pose, positions = (np.asarray(x) for x in poses())
    assert 0.5 <= floor.mean() < 1.0  # the folded side is lifted, the rest stays
    np.testing.assert_allclose(pose, positions, atol=1e-4)


def test_the_oracle_folds_a_flat_cloth_closer_than_random():
    # evaluate's loop on episodes 0-3 for both agents, their reset and step compiled once for both
    episodes = Episodes(_arena("side_fold"), range(4))
    oracle = episodes.run(build_agent("oracle_cloth_folding", ANALYTIC))
    random = episodes.run(build_agent("random"), jax.random.key(0))
    folded = np.asarray(oracle.metrics["normalised_fold_distance"])
    assert folded.max() < 0.8, folded  # 1: the unfolded cloth
    assert folded.mean() < np.asarray(random.metrics["normalised_fold_distance"]).mean() - 0.2


def _first_action(arena, agent):
    """The agent's first action and state on the arena's first two episodes, as one compiled call (run op by op,
    the reset and the act dispatch thousands of small programs)."""
    @jax.jit
    def first():
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(jnp.arange(2))
        agent_state = agent.init(jax.random.key(0), arena.spec, 2)
        return agent.act(agent_state, info, jax.random.key(1), arena.privileged(state))

    action, agent_state = first()
    return np.asarray(action), agent_state


def test_spare_pickers_idle_and_the_fold_starts_at_once_on_a_flat_cloth():
    # one corner moves in one_corner_inward: the second picker has nothing to fold
    arena = _arena("one_corner_inward", "pixel_pick_and_place(2)")
    oracle = build_agent("oracle_cloth_folding", ANALYTIC)
    action, state = _first_action(arena, oracle)
    np.testing.assert_array_equal(action[:, 4:], np.tile(cloth_actions.idle(1), (2, 1)))
    assert not np.array_equal(action[:, :4], action[:, 4:])
    assert np.asarray(state.folding).all()  # a flat start needs no flattening
    assert not np.asarray(oracle.reset(state, jnp.array([True, False])).folding)[0]


def test_a_crumpled_start_is_flattened_before_folding():
    arena = _arena("side_fold", initial="crumpled")
    action, state = _first_action(arena, build_agent("oracle_cloth_folding", ANALYTIC))
    assert not np.asarray(state.folding).any()


def test_the_oracle_needs_a_folding_task():
    with pytest.raises(AgentArenaMismatch, match="folding tasks"):
        build_agent("oracle_cloth_folding", ANALYTIC).check_fits(jarena.build_arena("cloth|particles:8,resolution:16"))


def test_the_lookahead_takes_the_fold_that_ends_nearest_the_goal():
    from jarena_agents.oracles.cloth_folding import fold_proposals
    from jarena_agents.planners.model import arena_model

    string = _string("diagonal_fold", particles=12)
    arena = jarena.build_arena(string)
    oracle = build_agent("oracle_cloth_folding", {"arena": string, "fractions": (0.7, 1.0)})
    model = arena_model(arena)

    @jax.jit
    def check(episodes):
        state, info = jax.vmap(lambda e: arena.reset(episode=e))(episodes)
        privileged = jax.vmap(arena.privileged)(state)
        taken, _ = oracle.act(oracle.init(jax.random.key(0), arena.spec, 2), info, jax.random.key(1), privileged)
        mesh = privileged.physics.mesh
        tried = jax.vmap(lambda x, g: fold_proposals(x, g.reshape(-1, 3), mesh, 1, "pixel", (0.7, 1.0)))(
            privileged.physics.positions, info.goal)
        def reward(start, a):
            return model.step(start, a)[1]

        return tried, taken, cloth_actions.each_score(privileged, tried, reward)

    actions, action, tried = (np.asarray(x) for x in check(jnp.arange(2)))
    # the taken fold's reward: that of the proposal it is (the proposals' rewards are computed as the oracle
    # computes them, which XLA compiles once; stepping the taken folds apart would compile the step again)
    same = (actions == action[:, None]).all(-1)
    assert same.any(-1).all(), (action, actions)  # the taken fold is one of the proposals
    taken = tried[np.arange(2), same.argmax(-1)]
    assert tried.shape == (2, 2 + 21 * 2)
    for i in range(2):
        assert len(np.unique(tried[i])) > 3, tried[i]  # the proposals differ
        assert taken[i] == tried[i].max(), (taken[i], tried[i])  # reward: -normalised fold distance
        assert taken[i] >= tried[i, 0]  # never worse than the analytic fold
        assert taken[i] > tried[i, 1]  # folding beats doing nothing on a flat cloth


def test_fold_proposals_move_each_edge_handle_toward_its_goal_and_lift_floor_handles_in_place():
    # per fraction f: the analytic fold, then each of the 16 edge handles alone placed the fraction f of the way to
    # its goal (those that stay on the floor too: they are lifted and set down in place, which drags the cloth a
    # few millimetres toward them), then the 4 corners pinched at their tips
    from jarena.arenas.cloth.mesh import ClothMesh
    from jarena.arenas.cloth.tasks import folded_goals
    from jarena.arenas.cloth.tools import WORKSPACE_HALF_WIDTH
    from jarena_agents.oracles.cloth_folding import fold_proposals

    mesh = ClothMesh(rows=12, cols=12, spacing=0.03)
    flat = jnp.asarray(mesh.rest_positions, jnp.float32) + jnp.array([0.02, -0.01, 0.4 * mesh.spacing])

    @jax.jit  # one program (op by op, the goal and the proposals dispatch hundreds of small ones)
    def fold(flat):
        goal = folded_goals(mesh, "side_fold", flat)[0]
        return goal, fold_proposals(flat, goal, mesh, 1, "world", (0.5, 1.0)), floor_layer(goal, mesh)

    goal, tried, floor = fold(flat)
    tried = np.asarray(tried) * WORKSPACE_HALF_WIDTH
    assert tried.shape == (2 + 21 * 2, 4)
    edges = cloth_actions.edge_handles(mesh)
    on_floor = np.asarray(floor)[edges]
    assert 0 < on_floor.sum() < 16, on_floor  # a side fold leaves about half its edge handles on the floor
    start, end = np.asarray(flat)[edges, :2], np.asarray(goal)[edges, :2]
    for k, f in enumerate((0.5, 1.0)):
        one = tried[2 + 21 * k + 1:2 + 21 * k + 17]
        np.testing.assert_allclose(one[:, :2], start, atol=1e-5)
        np.testing.assert_allclose(one[:, 2:], start + f * (end - start), atol=1e-5)
        np.testing.assert_allclose(one[on_floor, 2:], start[on_floor], atol=2e-3)  # lifted in place (within 2 mm)


def test_the_lookahead_needs_the_arena_it_simulates_and_fractions_toward_the_goal():
    with pytest.raises(ConfigError, match="arena='<arena string>'.*lookahead=False"):
        build_agent("oracle_cloth_folding")
    with pytest.raises(ConfigError, match="fractions.*in \\(0, 1.5\\]"):
        build_agent("oracle_cloth_folding", {"lookahead": False, "fractions": (0.5, 2.0)})
    with pytest.raises(ConfigError, match="fractions"):
        build_agent("oracle_cloth_folding", {"lookahead": False, "fractions": ()})


@pytest.mark.parametrize("cols", [16, 40])
def test_a_tip_pinch_grasps_each_corner_alone(cols):
    from jarena.arenas.cloth.mesh import ClothMesh
    from jarena.arenas.cloth.physics import ClothPhysics
    from jarena_agents.oracles.cloth_actions import tip_offsets

    mesh = ClothMesh.of_size(0.4, 0.4, cols=cols)
    physics = ClothPhysics(mesh, solver="xla")
    params = physics.default_params()
    rest = jnp.asarray(mesh.rest_positions)
    turn = jnp.array([[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]], jnp.float32)  # any pose in the plane
    state = physics.state_from_positions(rest @ turn.T + jnp.array([0.05, -0.02, float(params.particle_radius)]))
    corners = cloth_actions.handles(mesh)[:4]
    tips = state.positions[corners, :2] + tip_offsets(state.positions, mesh)

    @jax.jit
    def grasp(tip):  # the picker moves above the tip and closes at the pick height
        start = state.replace(picker_positions=jnp.concatenate([tip, jnp.full((1,), 0.01)])[None])
        return physics.step(start, jnp.array([[0.0, 0.0, 0.0, 1.0]]), params).held[0]

    for corner, tip in zip(corners, tips, strict=True):
        held = np.asarray(grasp(tip))
        assert held[held >= 0].tolist() == [corner]  # a pinch on the corner itself takes its neighbours too
        assert (np.asarray(grasp(state.positions[corner, :2])) >= 0).sum() >= 3
