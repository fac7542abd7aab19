"""The transporter agent on small synthetic scenes: trained on a few demonstrations it picks the object and places it
on its target with the right turn, in scenes it never saw; acting is the same at any batch size; bad configs and
arenas get clear errors."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena_agents
from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box, Dict
from jarena_agents.config import ConfigError, make_config
from jarena_agents.transporter.agent import TransporterConfig, build_model
from tests.agents.transporter.scenes import COLS, ROWS, infos, scenes

SPEC = ArenaSpec(observation=Dict(rgb=Box(0, 255, (ROWS, COLS, 3), np.uint8), height=Box(0.0, 0.28, (ROWS, COLS))),
                 action=Box(np.array([0, 0, 0, 0, -np.pi]), np.array([ROWS - 1, COLS - 1, ROWS - 1, COLS - 1, np.pi])),
                 name="tabletop")
# One stage of 8 channels (stride 1), 8 x 8 crops and quarter turns: 150 updates of one demonstration each fit 16
# demonstrations and place every one of 32 new scenes right (losses at ~1e-4 of their start).
TINY = dict(widths=(8,), head=8, crop=8, rotations=4, learning_rate=3e-3, augment=False)
UPDATES = 150
@pytest.fixture(scope="module")
def trained():
    """The agent's ``train`` from the train state its ``init_training`` makes of a dataset's arrays; then it acts on
    the training scenes and 32 new ones (one batch of 48), and on the first three new ones alone. One compiled
    program."""
    agent = jarena_agents.build_agent("transporter", TINY)
    model = build_model(make_config(TransporterConfig, TINY))
    demos, new = scenes(16, seed=0), scenes(32, seed=1)
    both = infos({k: np.concatenate([demos[k], new[k]]) for k in ("rgb", "height")})
    three = infos({k: new[k][:3] for k in ("rgb", "height")})

    @jax.jit
    def run(key):
        state = model.start(key, jax.tree_util.tree_map(jnp.asarray, demos))
        state, metrics = agent.train(state, None, UPDATES)
        policy = agent.policy(state, SPEC)
        return metrics, [agent.act(policy, info, key)[0] for info in (both, three)]

    metrics, (actions, three_actions) = jax.tree_util.tree_map(np.asarray, run(jax.random.key(0)))
    return dict(metrics=metrics, actions=[actions[:16], actions[16:], three_actions], demos=demos, new=new)


def _hits(actions: np.ndarray, demos: dict) -> tuple[float, float, float]:
    """Fractions of actions that pick the demonstrated pixel, place on the demonstrated pixel, and turn the same."""
    wanted = demos["action"]
    return (np.mean(np.all(actions[:, :2] == wanted[:, :2], 1)), np.mean(np.all(actions[:, 2:4] == wanted[:, 2:4], 1)),
            np.mean(np.abs(np.cos(actions[:, 4] - wanted[:, 4]) - 1) < 1e-4))


def test_a_tiny_transporter_learns_to_pick_and_place_and_turn_in_new_scenes(trained):
    metrics = trained["metrics"]
    assert metrics["loss"].shape == (UPDATES,) and np.all(metrics["episodes"] == 0)
    for name in ("attention_loss", "transport_loss"):
        assert np.mean(metrics[name][-10:]) < 0.01 * np.mean(metrics[name][:10]), name
    seen, unseen, _ = trained["actions"]
    assert _hits(seen, trained["demos"]) == (1.0, 1.0, 1.0)
    # turns of all four kinds, learnt by matching turned crops: right in scenes it never saw
    assert set(np.round(trained["new"]["action"][:, 4] / (np.pi / 2)).astype(int) % 4) == {0, 1, 2, 3}
    assert _hits(unseen, trained["new"]) == (1.0, 1.0, 1.0)


def test_acting_is_the_same_at_any_batch_size(trained):
    _, unseen, three = trained["actions"]
    assert three.shape == (3, 5) and three.dtype == np.float32
    np.testing.assert_array_equal(three, unseen[:3])


def test_bad_configs_and_arenas_get_clear_errors(pendulum):
    with pytest.raises(ConfigError, match="crop must be even"):
        jarena_agents.build_agent("transporter", {"crop": 9})
    with pytest.raises(ConfigError, match="widths must be a non-empty list"):
        jarena_agents.build_agent("transporter", {"widths": []})
    with pytest.raises(ConfigError, match="unknown config key.*'crop_size'"):
        jarena_agents.build_agent("transporter", {"crop_size": 64})
    agent = jarena_agents.build_agent("transporter", TINY)
    with pytest.raises(ConfigError, match="'rgb' uint8 \\(H, W, 3\\) and height map 'height'"):
        agent.init(jax.random.key(0), pendulum.spec, 1)
    spec = ArenaSpec(observation=SPEC.observation, action=Box(-1.0, 1.0, (5,)), name="rescaled")
    with pytest.raises(ConfigError, match="rows 0..23, columns 0..15"):
        agent.init(jax.random.key(0), spec, 1)
