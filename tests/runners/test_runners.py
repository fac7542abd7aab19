import importlib
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import jarena
import jarena_agents


@pytest.fixture(scope="module")
def arena():
    return jarena.build_arena("classic|domain:cartpole,task:balance")


def test_evaluate_aggregates_and_matches_run(arena):
    agent = jarena_agents.build_agent("random")
    result = jarena.evaluate(agent, arena, jax.random.key(0), episodes=[0, 1, 2, 3])
    assert result.returns.shape == (4,) and list(result.episodes) == [0, 1, 2, 3]
    np.testing.assert_array_equal(result.returns, result.lengths)  # reward 1 per step
    s = result.summary()
    assert s["return_ci95_low"] < s["return_mean"] < s["return_ci95_high"]
    assert s["return_std"] == pytest.approx(np.std(result.returns, ddof=1))
    assert "return" in result.table() and "success rate" in result.table()
    # the same episode through run() with the no-op agent gives the same length as evaluate
    noop = jarena_agents.build_agent("no_op")
    ev = jarena.evaluate(noop, arena, jax.random.key(0), episodes=[2])
    traj = jarena.run(noop, arena, jax.random.key(5), episode=2)
    assert int(traj.length) == int(ev.lengths[0])
    assert float(traj.episode_return) == float(ev.returns[0])
    assert traj.infos.reward.shape == (500,) and traj.actions.shape == (500,)
    assert not bool(traj.valid[int(traj.length)])


def test_evaluate_is_deterministic_and_independent_of_batch(arena):
    agent = jarena_agents.build_agent("no_op")
    full = jarena.evaluate(agent, arena, jax.random.key(0))
    some = jarena.evaluate(agent, arena, jax.random.key(1), episodes=[3, 7])
    np.testing.assert_array_equal(full.returns[[3, 7]], some.returns)


def test_evaluate_checks_for_the_end_every_few_steps_without_changing_results(arena, monkeypatch):
    evaluate_module = importlib.import_module("jarena.runners.evaluate")  # (the package exports the function)

    assert [evaluate_module.steps_per_check(m, 2) for m in (10, 30, 63, 64, 200, 1000)] == [1, 1, 1, 2, 5, 8]
    assert evaluate_module.steps_per_check(1000, 1) == 1
    agent = jarena_agents.build_agent("random")
    runs = {}
    for block in (1, 3, 7):  # 7 does not divide 30: its last block runs past the cap, frozen
        monkeypatch.setattr(evaluate_module, "steps_per_check", lambda max_steps, devices, block=block: block)
        evaluate_module._compiled_episodes.cache_clear()
        runs[block] = evaluate_module.run_episodes(agent, arena, jax.random.key(0), episodes=range(16), max_steps=30,
                                                   filmed=3)
    evaluate_module._compiled_episodes.cache_clear()
    base, base_film = runs[1]
    assert (base.lengths < 30).sum() >= 4 and (base.lengths == 30).sum() >= 1, base.lengths  # ended early, capped
    for block in (3, 7):
        result, film = runs[block]
        np.testing.assert_array_equal(result.lengths, base.lengths)
        np.testing.assert_array_equal(result.returns, base.returns)
        np.testing.assert_array_equal(result.successes, base.successes)
        for a, b in zip(jax.tree_util.tree_leaves(film), jax.tree_util.tree_leaves(base_film), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_evaluate_policies_equals_evaluating_each_policy_alone(arena):
    """Three policies (PPO's initial networks from three keys, acting greedily) stacked on a leading axis: one
    compiled batch gives each the results evaluate gives it alone with the same key; bad stacks are refused."""
    agent = jarena_agents.build_agent("ppo", {"num_arenas": 4, "total_steps": 4096})
    policies = [agent.policy(agent.init_training(jax.random.key(s), arena), arena.spec, True) for s in range(3)]
    stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *policies)
    together = jarena.evaluate_policies(agent, arena, stacked, jax.random.key(7), split="val")
    assert len(together) == 3
    for policy, result in zip(policies, together, strict=True):
        alone = jarena.validate(agent, arena, jax.random.key(7), agent_state=policy)
        np.testing.assert_array_equal(result.returns, alone.returns)
        np.testing.assert_array_equal(result.episodes, alone.episodes)
        assert result.split == "val" and result.summary()["episodes"] == arena.num_val_episodes
    assert len({tuple(r.returns) for r in together}) == 3  # three different policies
    leaves, tree = jax.tree_util.tree_flatten(stacked)
    ragged = jax.tree_util.tree_unflatten(tree, [leaves[0][:2], *leaves[1:]])
    with pytest.raises(ValueError, match="stacked on a leading policy axis"):
        jarena.evaluate_policies(agent, arena, ragged, jax.random.key(7))


def test_validate_uses_the_val_split(arena):
    result = jarena.validate(jarena_agents.build_agent("no_op"), arena)
    assert result.split == "val" and list(result.episodes) == list(arena.episodes("val"))


def test_evaluate_bad_split(arena):
    with pytest.raises(ValueError, match="'eval' or 'val'"):
        jarena.evaluate(jarena_agents.build_agent("random"), arena, split="train")


def test_perform_parallel_auto_resets(arena):
    rollout = jarena.perform_parallel(jarena_agents.build_agent("random"), arena, jax.random.key(0), 8, 100)
    assert rollout.infos.reward.shape == (100, 8)
    assert int(rollout.infos.done.sum()) > 8  # random cartpole episodes last ~20 steps
    again = jarena.perform_parallel(jarena_agents.build_agent("random"), arena, jax.random.key(0), 8, 10,
                                    start=(rollout.state, rollout.info))
    continued = ~np.asarray(again.infos.done[0])  # episodes that did not end on the first new step
    np.testing.assert_array_equal(np.asarray(again.infos.step[0])[continued],
                                  np.asarray(rollout.info.step)[continued] + 1)


def test_perform_parallel_shards_over_devices():
    code = textwrap.dedent("""
        import jax, jarena, jarena_agents
        assert jax.local_device_count() == 4
        arena = jarena.build_arena("classic|domain:cartpole")
        r = jarena.perform_parallel(jarena_agents.build_agent("random"), arena, jax.random.key(0), 8, 20)
        assert len(r.state.physics.x.sharding.device_set) == 4, r.state.physics.x.sharding
        try:
            jarena.perform_parallel(jarena_agents.build_agent("random"), arena, jax.random.key(0), 6, 5)
        except ValueError as e:
            assert "multiple of 4" in str(e)
        else:
            raise SystemExit("no error for an uneven batch")
        print("sharded ok")
    """)
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "sharded ok" in out.stdout, out.stderr[-3000:]
