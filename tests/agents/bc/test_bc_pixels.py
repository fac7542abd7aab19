"""BC from pixels: the cloth arena's rgb camera through a CNN, the mixture policy and the quarter-turn
augmentation (`bc` clones the cloth oracle from pixels)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.data import TrajectoryDataset, configs_for
from jarena.training import train_and_evaluate
from jarena_agents.bc.agent import read_dataset
from jarena_agents.config import ConfigError

CLOTH = "cloth|particles:8,resolution:24,horizon:3,depth:false,mask:false,eval_episodes:4,val_episodes:2"
SMALL_CNN = ((8, 4, 2), (8, 3, 2))


@pytest.fixture(scope="module")
def cloth_demos(tmp_path_factory):
    """Analytic-pull oracle demonstrations on small crumpled cloths: rgb observations only."""
    arena = jarena.build_arena(CLOTH)
    path = str(tmp_path_factory.mktemp("demos") / "cloth")
    oracle = jarena_agents.build_agent("oracle_cloth_flattening", {"lookahead": False})
    with TrajectoryDataset(path, "w", **configs_for(arena)) as dataset:
        jarena.collect(oracle, arena, dataset, 24, key=jax.random.key(1), progress=False)
    return arena, path


def _info_of(arena, images):
    """An info for a batch of the arena's rgb ``images``, every other field zeros (the BC policy reads only the
    observation and the goal): its shapes are traced, not reset (a compiled crumpled reset costs seconds)."""
    shapes = jax.eval_shape(lambda key: jarena.batch_reset(arena, key, len(images))[1], jax.random.key(0))
    return jax.tree_util.tree_map(lambda s: np.zeros(s.shape, s.dtype), shapes).replace(
        observation={"rgb": jnp.asarray(images)})


def _train(arena, path, steps, evaluate=True, **config):
    """BC trained for ``steps`` updates (in 20 chunks) and evaluated; without ``evaluate``, the run is given one
    spare chunk and stopped before it, so it trains the same and skips the evaluation's compile (~15 s)."""
    agent = jarena_agents.build_agent("bc", {"dataset": path, "cnn": SMALL_CNN, "hidden": (64,), "batch_size": 32,
                                             "total_steps": steps, **config})
    if evaluate:
        return agent, train_and_evaluate(agent, arena, jax.random.key(0), validate_every=0, progress=False)
    chunk = steps // 20
    assert chunk * 20 == steps
    return agent, train_and_evaluate(agent, arena, jax.random.key(0), total_steps=steps + chunk, chunk_updates=chunk,
                                     stop_after_chunks=20, validate_every=0, progress=False)


def test_bc_learns_the_pick_and_place_from_the_image_alone(cloth_demos):
    """The arena observes only rgb: the network's sole input is the CNN's, so fitting the oracle's actions
    better than their mean (the best constant) means it reads the images."""
    arena, path = cloth_demos
    assert set(arena.spec.observation.spaces) == {"rgb"}
    agent, result = _train(arena, path, 400, learning_rate=3e-3)
    assert "encoder" in result.train_state.params["params"]  # a CNN torso, not an MLP over flattened pixels
    host = read_dataset(path, arena, 1)
    actions = host["data"]["action"]
    starts = np.concatenate([[0], np.cumsum(host["lengths"])[:-1]]) + np.arange(len(host["lengths"]))
    # each action's observation
    rows = np.concatenate([s + np.arange(n) for s, n in zip(starts, host["lengths"], strict=True)])
    policy = agent.policy(result.train_state, arena.spec, True)
    info = _info_of(arena, host["data"]["observation"]["rgb"][rows])
    predicted, _ = jax.jit(agent.act)(policy, info, jax.random.key(2))
    mse = float(np.mean(np.sum((np.asarray(predicted) - actions) ** 2, -1)))
    constant = float(np.mean(np.sum((actions - actions.mean(0)) ** 2, -1)))
    print(f"bc from pixels: mse {mse:.4f}, best constant {constant:.4f}")
    assert mse < 0.5 * constant
    assert result.evaluation.episodes.size == 4  # it acted in the arena from its camera


def test_mixture_policy_keypoints_and_rotate90_augmentation_train_and_act(cloth_demos):
    arena, path = cloth_demos
    # trained, not evaluated (this test acts itself, below)
    agent, result = _train(arena, path, 60, evaluate=False, policy="mixture", components=3, augment="rotate90",
                           cnn_output="spatial_softmax", cnn_padding="SAME")
    assert len(result.history) == 20
    assert result.train_state.params["params"]["mlp"]["Dense_0"]["kernel"].shape[0] == 2 * SMALL_CNN[-1][0]
    losses = [h["loss"] for h in result.history]
    assert np.isfinite(losses).all() and losses[-1] < losses[0]
    # five of the demonstrations' camera images (run op by op, the reset and the network dispatch hundreds of
    # small programs; compiled, each is one)
    info = _info_of(arena, read_dataset(path, arena, 1)["data"]["observation"]["rgb"][:5])
    act = jax.jit(agent.act)
    for deterministic in (True, False):
        action, _ = act(agent.policy(result.train_state, arena.spec, deterministic), info, jax.random.key(2))
        assert action.shape == (5, 4) and bool(jnp.all(jnp.abs(action) <= 1.0))
    again, _ = act(agent.policy(result.train_state, arena.spec, True), info, jax.random.key(7))
    first, _ = act(agent.policy(result.train_state, arena.spec, True), info, jax.random.key(2))
    np.testing.assert_array_equal(first, again)  # eval mode: the most probable component's mean, no noise


def test_rotate90_needs_image_point_actions_and_images_only(tmp_path):
    pendulum = jarena.build_arena("classic|domain:pendulum,task:swingup")
    with TrajectoryDataset(tmp_path / "p", "w", **configs_for(pendulum)) as dataset:
        jarena.collect(jarena_agents.build_agent("random"), pendulum, dataset, 2, key=jax.random.key(0),
                       progress=False)
    agent = jarena_agents.build_agent("bc", {"dataset": str(tmp_path / "p"), "augment": "rotate90"})
    with pytest.raises(ConfigError, match="no image observations"):
        agent.init_training(jax.random.key(0), pendulum)
    with pytest.raises(ConfigError, match="unknown augment 'flip'.*rotate90"):
        jarena_agents.build_agent("bc", {"augment": "flip"})
    with pytest.raises(ConfigError, match="unknown cnn_output 'keypoints'.*spatial_softmax"):
        jarena_agents.build_agent("bc", {"cnn_output": "keypoints"})
    with_depth = jarena.build_arena("cloth|particles:8,resolution:16,horizon:2")
    with pytest.raises(ConfigError, match="more than images"):
        jarena_agents.augment.check_rotate90(with_depth.spec, "bc")
