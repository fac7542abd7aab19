"""The transporter agent on ``raven|task:block-insertion``: it reads two oracle episodes collected with
``jarena.collect``, takes an update and acts within the arena's action spec; the oracle's yaw turns the block the
way the transport's crops turn.

Collecting compiles the arena's MJX programs, some 43 s of CPU with XLA's default options; it runs in a subprocess
with XLA's quick options (19 s), which change how fast the compiled code runs, not what it computes. The collecting
arenas replay their first episode's start (``auto_reset:repeat``), so the collect program holds no reset, and run
one step (the oracle's episodes take one action): the same two trajectories as the defaults, collected sooner.
"""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.data import TrajectoryDataset
from jarena_agents.config import ConfigError
from jarena_agents.transporter import data, se2
from jarena_agents.transporter.layout import layout_of
from tests.agents.transporter.scenes import infos

ARENA = "raven|task:block-insertion"
QUICK_XLA = ("--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true "
             "--xla_cpu_use_fusion_emitters=false")
COLLECT = """
import sys, jax, jarena, jarena_agents
from jarena.platform import enable_compilation_cache
enable_compilation_cache(min_compile_secs=0)  # the suite's cache (JARENA_COMPILATION_CACHE, set by conftest.py)
arena = jarena.build_arena(sys.argv[2])
with jarena.TrajectoryDataset(sys.argv[1], "w", **jarena.data.configs_for(arena)) as dataset:
    jarena.collect(jarena_agents.build_agent("oracle_raven"), arena, dataset, 2, key=jax.random.key(0),
                   chunk_steps=1, progress=False)
"""
TINY = dict(widths=(8,), head=8, crop=8, rotations=4)
BLOCK = (255, 87, 89)  # the block's colour in the heightmap


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    path = str(tmp_path_factory.mktemp("raven") / "oracle")
    env = dict(os.environ, XLA_FLAGS=(os.environ.get("XLA_FLAGS", "") + " " + QUICK_XLA).strip(), JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", COLLECT, path, ARENA + ",auto_reset:repeat"], env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-4000:]
    return path


def test_the_oracle_turns_the_block_as_the_transport_turns_its_crops(demos):
    """The block's pixels around the pick, turned by the oracle's yaw, are where the block lies around the place
    point after the action (and not when turned the other way): the transport's crop at the demonstrated yaw bin
    shows the block as it will lie."""
    with TrajectoryDataset(demos, "r") as dataset:
        trajectories = [dataset.get_trajectory(i) for i in range(2)]
    crop = jax.jit(lambda image, centre, yaw: se2.rotated_crops(image, centre, yaw[None], 64)[0])
    for trajectory in trajectories:
        before, after = (np.all(trajectory["observation"]["rgb"][i] == BLOCK, -1)[..., None].astype(np.float32)
                         for i in (0, 1))
        action = trajectory["action"]["action"][0]
        placed = np.asarray(crop(after, action[2:4], np.float32(0.0)))

        def overlap(yaw):
            turned = np.asarray(crop(before, np.round(action[:2]), yaw))
            return np.sum(turned * placed) / np.sum(np.maximum(turned, placed))

        assert before.sum() > 300 and overlap(action[4]) > 0.85 and overlap(-action[4]) < 0.5, action


def test_transporter_trains_on_oracle_demonstrations_and_acts_in_the_action_spec(demos):
    arena = jarena.build_arena(ARENA)
    host = data.read_dataset(demos, arena, layout_of(arena.spec))
    with TrajectoryDataset(demos, "r") as dataset:
        first = [dataset.get_trajectory(i)["observation"] for i in range(2)]
        assert dataset.lengths().tolist() == [1, 1]  # the oracle inserts the block in one action
    assert host["rgb"].shape == (2, 320, 160, 3) and host["action"].shape == (2, 5)
    np.testing.assert_array_equal(host["height"][1], first[1]["height"][0])  # the image before each action

    agent = jarena_agents.build_agent("transporter", dict(TINY, dataset=demos))
    info = infos({"rgb": host["rgb"], "height": host["height"]})  # the agent reads only the images

    @jax.jit
    def run(key):
        start = agent.init_training(key, arena)
        state, metrics = agent.train(start, arena, 1)
        actions, _ = agent.act(agent.policy(state, arena.spec), info, key)
        changed = jax.tree_util.tree_map(lambda a, b: jnp.any(a != b), start.params, state.params)
        return state.update, metrics, changed, actions, jax.vmap(arena.action_spec.contains)(actions)

    update, metrics, changed, actions, in_spec = jax.tree_util.tree_map(np.asarray, run(jax.random.key(0)))
    assert int(update) == 1 and np.all(np.isfinite(metrics["loss"])) and float(metrics["loss"][0]) > 0
    assert all(jax.tree_util.tree_leaves(changed))  # every layer of the three networks learnt
    assert actions.shape == (2, 5) and actions.dtype == np.float32
    assert bool(np.all(in_spec))
    np.testing.assert_array_equal(actions[:, :4], np.round(actions[:, :4]))  # pixels
    assert set(np.round(actions[:, 4] / (np.pi / 2)).astype(int)) <= {-1, 0, 1, 2}  # one of 4 yaws


def test_raven_arenas_that_do_not_act_in_pixels_and_missing_datasets_get_clear_errors():
    agent = jarena_agents.build_agent("transporter", TINY)
    with pytest.raises(ConfigError, match="in image pixels.*rescale"):
        agent.init(jax.random.key(0), jarena.build_arena(ARENA + ",action:rescale(-1,1)").spec, 1)
    with pytest.raises(ValueError, match="set its config key dataset=PATH"):
        agent.init_training(jax.random.key(0), jarena.build_arena(ARENA))
