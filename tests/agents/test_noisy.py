import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena_agents import noisy

PENDULUM = "classic|domain:pendulum,task:swingup"  # torque in [-2, 2]: a half range of 2


def _actions(agent, arena, num, key=1):
    state = agent.init(jax.random.key(0), arena.spec, num)
    arena_state, info = jarena.batch_reset(arena, jax.random.key(0), num)
    privileged = arena.privileged(arena_state) if agent.privileged else None
    action, _ = jax.jit(agent.act)(state, info, jax.random.key(key), privileged)
    return np.asarray(action)


def test_no_noise_acts_as_the_bare_agent_over_whole_episodes():
    arena = jarena.build_arena(PENDULUM)
    oracle = jarena_agents.build_agent("oracle_pendulum")
    bare = jarena.evaluate(oracle, arena, jax.random.key(3))
    wrapped = jarena.evaluate(noisy(oracle), arena, jax.random.key(3))
    np.testing.assert_array_equal(wrapped.returns, bare.returns)
    assert noisy(oracle).name == "noisy(oracle_pendulum)"


def test_gaussian_noise_has_the_asked_spread_in_half_ranges_and_stays_in_the_box():
    arena = jarena.build_arena(PENDULUM)
    oracle = jarena_agents.build_agent("oracle_pendulum")
    clean = _actions(oracle, arena, 4096)
    perturbed = _actions(noisy(oracle, action_noise=0.05), arena, 4096)
    inside = np.abs(clean) < 1.5  # away from the bounds, where clipping does not shorten the noise
    assert inside.sum() > 500
    spread = (perturbed - clean)[inside].std()
    assert spread == pytest.approx(0.05 * 2.0, rel=0.1)
    wide = _actions(noisy(oracle, action_noise=3.0), arena, 4096)
    assert wide.min() == -2.0 and wide.max() == 2.0  # clipped to the action spec, and reaching it


def test_random_actions_replace_the_asked_fraction_uniformly():
    arena = jarena.build_arena(PENDULUM)
    oracle = jarena_agents.build_agent("oracle_pendulum")
    clean = _actions(oracle, arena, 8192)
    mixed = _actions(noisy(oracle, random_fraction=0.3), arena, 8192)
    replaced = mixed != clean
    assert replaced.mean() == pytest.approx(0.3, abs=4 * np.sqrt(0.3 * 0.7 / 8192))
    drawn = mixed[replaced]
    assert drawn.min() >= -2.0 and drawn.max() <= 2.0
    assert np.histogram(drawn, bins=4, range=(-2, 2))[0].min() > 0.2 * len(drawn)  # uniform over the box
    everything = _actions(noisy(oracle, random_fraction=1.0), arena, 8192)
    assert (everything != clean).mean() > 0.999


def test_discrete_actions_are_replaced_never_perturbed_and_the_same_key_gives_the_same_actions():
    arena = jarena.build_arena("classic|domain:cartpole")
    oracle = jarena_agents.build_agent("oracle_cartpole")
    clean = _actions(oracle, arena, 4096)
    assert np.array_equal(_actions(noisy(oracle, action_noise=1.0), arena, 4096), clean)
    mixed = _actions(noisy(oracle, random_fraction=0.5), arena, 4096)
    assert set(np.unique(mixed)) <= {0, 1} and mixed.dtype == clean.dtype
    assert 0.15 < (mixed != clean).mean() < 0.35  # half replaced, half of those by the other action
    np.testing.assert_array_equal(_actions(noisy(oracle, random_fraction=0.5), arena, 4096), mixed)
    assert not np.array_equal(_actions(noisy(oracle, random_fraction=0.5), arena, 4096, key=2), mixed)


def test_a_noisy_oracle_still_solves_more_than_random_and_less_than_itself():
    arena = jarena.build_arena(PENDULUM)
    oracle = jarena_agents.build_agent("oracle_pendulum")
    returns = {name: jarena.evaluate(agent, arena, jax.random.key(0)).summary()["return_mean"]
               for name, agent in [("oracle", oracle), ("noisy", noisy(oracle, action_noise=0.3,
                                                                        random_fraction=0.2)),
                                   ("random", jarena_agents.build_agent("random"))]}
    assert returns["random"] < returns["noisy"] < returns["oracle"]


@pytest.mark.parametrize("kwargs, message", [
    ({"action_noise": -0.1}, "action_noise must be a finite number >= 0, got -0.1"),
    ({"action_noise": float("nan")}, "action_noise must be a finite number >= 0"),
    ({"random_fraction": 1.5}, r"random_fraction must be a number in \[0, 1\], got 1.5"),
])
def test_bad_amounts_are_refused_naming_the_valid_range(kwargs, message):
    with pytest.raises(ValueError, match=message):
        noisy(jarena_agents.build_agent("random"), **kwargs)


def test_collect_stores_noisier_demonstrations_and_refuses_bad_amounts(tmp_path):
    def collect(out, *flags):
        return subprocess.run([sys.executable, "-m", "jarena.cli", "collect", "oracle_pendulum", PENDULUM,
                               "--out", str(tmp_path / out), "--trajectories", "4", "--no-progress", *flags],
                              capture_output=True, text=True, timeout=300)

    assert collect("clean").returncode == 0
    done = collect("noisy", "--action-noise", "0.2", "--random-actions", "0.2")
    assert done.returncode == 0, done.stderr
    clean = jarena.TrajectoryDataset(tmp_path / "clean")
    mixed = jarena.TrajectoryDataset(tmp_path / "noisy")
    rows = int(clean.lengths().sum())
    assert int(mixed.lengths().sum()) == rows  # the same episodes (same seed), other actions
    clean_actions, mixed_actions = clean.rows("action/action", 0, rows), mixed.rows("action/action", 0, rows)
    assert np.abs(clean_actions).max() <= 2 and np.abs(mixed_actions).max() <= 2
    assert not np.array_equal(clean_actions, mixed_actions)
    bad = collect("bad", "--random-actions", "2")
    assert bad.returncode != 0 and "--random-actions must be a probability in [0, 1], got 2.0" in bad.stderr
    assert not (tmp_path / "bad").exists()
    assert jnp.all(jnp.isfinite(mixed_actions))


def test_structured_actions_perturb_their_float_boxes_and_keep_the_rest():
    from jarena.core import spec as specs
    from jarena_agents.noisy import _perturb

    spec = specs.Dict(place=specs.Box(0.0, 10.0, (3,)), grip=specs.Discrete(2),
                      pair=specs.Tuple([specs.Box(-1.0, 1.0, (2,)), specs.Box(0, 5, (1,), jnp.int32)]))
    action = {"place": jnp.full((3,), 5.0), "grip": jnp.asarray(1, jnp.int32),
              "pair": (jnp.zeros((2,)), jnp.asarray([3], jnp.int32))}
    keys = jax.random.split(jax.random.key(0), 2000)
    out = jax.vmap(lambda k: _perturb(spec, action, k, 0.1))(keys)
    assert np.asarray(out["place"]).std() == pytest.approx(0.1 * 5.0, rel=0.1)  # half range 5
    assert np.asarray(out["pair"][0]).std() == pytest.approx(0.1 * 1.0, rel=0.1)  # half range 1
    assert np.all(np.asarray(out["grip"]) == 1) and np.all(np.asarray(out["pair"][1]) == 3)
    assert np.asarray(out["place"]).min() >= 0 and np.asarray(out["pair"][0]).max() <= 1
