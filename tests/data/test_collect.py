import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.data import TrajectoryDataset, configs_for, resize_images


@pytest.fixture(scope="module")
def cartpole():
    return jarena.build_arena("classic|domain:cartpole,task:balance")


def _replay(arena, trajectory, observe=None):
    """Re-runs the stored episode with the stored actions; returns its observations, rewards and flags."""
    step = jax.jit(arena.step)
    state, info = arena.reset(episode=trajectory["episode"])
    observations, rewards, terminated, truncated = [info.observation], [], [], []
    for action in trajectory["action"]["action"]:
        state, info = step(state, action)
        observations.append(info.observation)
        rewards.append(info.reward), terminated.append(info.terminated), truncated.append(info.truncated)
    observations = jax.tree_util.tree_map(lambda *x: np.stack(x), *observations)
    if observe is not None:
        observations = jax.vmap(observe)(observations)
    return observations, np.array(rewards), np.array(terminated), np.array(truncated)


def test_collected_trajectories_replay_exactly_across_chunk_boundaries(cartpole, tmp_path):
    agent = jarena_agents.build_agent("random")
    with TrajectoryDataset(tmp_path / "d", "w", **configs_for(cartpole)) as ds:
        # random cart-pole episodes last ~20 steps; chunks of 7 steps cut through them
        indices = jarena.collect(agent, cartpole, ds, 9, key=jax.random.key(0), num_arenas=4, chunk_steps=7,
                                 progress=False)
        assert indices == list(range(9)) and ds.num_trajectories() == 9
    ds = TrajectoryDataset(tmp_path / "d")
    assert len(set(ds.episodes().tolist())) == 9
    for trajectory in ds:
        observations, rewards, terminated, truncated = _replay(cartpole, trajectory)
        # float32 drift between the batched collection program and this per-step replay (different fusion)
        np.testing.assert_allclose(trajectory["observation"]["state"], observations["state"], rtol=1e-4, atol=1e-5)
        np.testing.assert_array_equal(trajectory["reward"], rewards)
        np.testing.assert_array_equal(trajectory["terminated"], terminated)
        assert (terminated | truncated)[-1] and not (terminated | truncated)[:-1].any()
    # the same key collects the same trajectories
    with TrajectoryDataset(tmp_path / "again", "w", **configs_for(cartpole)) as again:
        jarena.collect(agent, cartpole, again, 9, key=jax.random.key(0), num_arenas=4, chunk_steps=7, progress=False)
        for a, b in zip(again, ds, strict=True):
            np.testing.assert_array_equal(a["action"]["action"], b["action"]["action"])


def _pixel_arena(base):
    def observe(physics, params):
        ramp = jnp.linspace(0.0, 1.0, 16)
        image = (jnp.clip(physics.x + 2.4, 0.0, 4.8) / 4.8 * 255.0 * ramp[:, None, None]
                 + 40.0 * jnp.clip(physics.theta + 0.3, 0.0, 0.6) * ramp[None, :, None] * jnp.ones(3))
        return {"state": base.sensor.observe(physics, params)["state"], "rgb": image.astype(jnp.uint8)}

    sensor = jarena.Sensor(observe=observe, name="pixels")
    return jarena.Arena(dynamics=base.dynamics, sensor=sensor, task=base.task, tool=base.tool, name="cartpole-pixels")


def test_collect_stores_resized_uint8_images(cartpole, tmp_path):
    arena = _pixel_arena(cartpole)
    observe = resize_images((8, 8))
    configs = configs_for(arena, observe=observe, compression="zstd")
    assert configs["obs_config"]["rgb"].shape == (8, 8, 3) and configs["obs_config"]["rgb"].dtype == "uint8"
    agent = jarena_agents.build_agent("oracle_cartpole", {"k_theta": -2.0})  # falls quickly
    with TrajectoryDataset(tmp_path / "pix", "w", **configs) as ds:
        jarena.collect(agent, arena, ds, 3, key=jax.random.key(1), num_arenas=3, chunk_steps=50, observe=observe,
                       progress=False)
    ds = TrajectoryDataset(tmp_path / "pix")
    trajectory = ds.get_trajectory(0)
    rgb = trajectory["observation"]["rgb"]
    assert rgb.dtype == np.uint8 and rgb.shape[1:] == (8, 8, 3) and len(np.unique(rgb)) > 10
    observations = _replay(arena, trajectory, observe)[0]
    np.testing.assert_array_equal(trajectory["observation"]["rgb"], observations["rgb"])


def test_collect_needs_a_time_limit(cartpole, tmp_path):
    endless = dataclasses.replace(cartpole, task=dataclasses.replace(cartpole.task, horizon=None))
    if endless.max_episode_steps is not None:
        pytest.skip("cannot build an arena without a horizon here")
    with TrajectoryDataset(tmp_path / "e", "w", **configs_for(cartpole)) as ds, \
            pytest.raises(ValueError, match="no time limit"):
        jarena.collect(jarena_agents.build_agent("random"), endless, ds, 1, key=jax.random.key(0))


def test_the_example_collects_and_resumes(tmp_path, capsys):
    import importlib.util
    import os

    path = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "collect_oracle_demos.py")
    spec = importlib.util.spec_from_file_location("collect_oracle_demos", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    args = ["--agent", "oracle_cartpole", "--arena", "classic|domain:cartpole,task:balance", "--out",
            str(tmp_path / "demos"), "--trajectories", "2", "--arenas", "2"]
    example.main(args)
    example.main(args)
    assert "trajectories=4, steps=2000" in capsys.readouterr().out  # the oracle balances all 500 steps


def test_the_default_chunk_runs_no_step_that_cannot_be_stored(tmp_path, monkeypatch):
    """Expensive agents (a cloth oracle simulating its proposals) pay only for the episodes asked for: 5
    episodes of 7 steps on 3 arenas take chunks of 14 steps (2 episodes each), not 100."""
    import sys

    collect_module = sys.modules["jarena.data.collect"]  # the attribute jarena.data.collect is the function
    arena = jarena.build_arena("classic|domain:pendulum,task:swingup,time_limit:7")
    calls = []
    real = collect_module.perform_parallel
    monkeypatch.setattr(collect_module, "perform_parallel",
                        lambda agent, arena, key, num, steps, **kw: calls.append(steps) or real(agent, arena, key, num,
                                                                                                steps, **kw))
    with TrajectoryDataset(tmp_path / "d", "w", **configs_for(arena)) as ds:
        jarena.collect(jarena_agents.build_agent("random"), arena, ds, 5, key=jax.random.key(0), num_arenas=3,
                       progress=False)
        assert ds.num_trajectories() == 5
    assert calls == [14]
