"""The diffusion agent: trained from a dataset as bc is, it clones an oracle and samples every mode of its
demonstrations; acting is the same at any batch size, replays its action chunks and replans; bad configs get clear
errors."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jarena
import jarena_agents
from jarena.core.arena import ArenaSpec
from jarena.core.spec import Box, Dict
from jarena.core.types import Info
from jarena.data import DatasetError, TrajectoryDataset, configs_for
from jarena.training import train_and_evaluate
from jarena_agents.config import ConfigError
from jarena_agents.diffusion import data

PENDULUM = "classic|domain:pendulum,time_limit:24"
MODE = 1.5  # the demonstrator pushes with +1.5 or -1.5 for a whole episode, at random
# A tiny U-Net (one level of 8 channels): enough for two modes, and cheap to compile. Over training keys 0-2 (two
# sampling keys each), 800 updates leave 0-1.2% of the samples between the modes and the last chunk's loss at
# 0.036-0.057 of the first's; 400 updates leave 3-6%.
TINY = dict(down_dims=(8,), groups=2, step_embedding=16, horizon=8, obs_horizon=2, action_steps=4, batch_size=64,
            learning_rate=1e-2, warmup_steps=20, total_steps=800)


POINT_MASS = "classic|domain:point_mass,time_limit:50"
# A one-level U-Net of 16 channels trained for 1,500 updates at a learning rate well above the paper's (its 1e-4 with
# 500 warm-up steps is for runs of 100,000 updates or more): on 16 oracle episodes it returns -19 to -21 (oracle -17,
# random -39), and the actions it plans for the demonstrated observations are 0.42 of the demonstrated actions'
# spread away from them. 600 updates return about -27; 400 updates at 1e-2 with 8 channels, random's.
CLONE = dict(down_dims=(16,), groups=4, step_embedding=16, horizon=8, obs_horizon=2, action_steps=4, batch_size=64,
             learning_rate=3e-3, warmup_steps=20, total_steps=1500)


def two_mode_demonstrations(path, arena, count: int = 16, length: int = 24) -> np.ndarray:
    """``count`` trajectories with two equally good actions: each pushes one way for its whole length, +1.5 or -1.5
    at random, from random pendulum states. Written straight to a dataset of the arena's schema (a compiled
    collection rollout would cost seconds; the agent reads the dataset alike). Returns every action."""
    rng = np.random.default_rng(1)
    signs = rng.choice([-1.0, 1.0], count)
    with TrajectoryDataset(path, "w", **configs_for(arena)) as dataset:
        dataset.add_trajectories([dict(observations={"state": rng.uniform(-1, 1, (length + 1, 3)).astype(np.float32)},
                                       actions=np.full((length, 1), MODE * sign, np.float32)) for sign in signs])
    return np.repeat(MODE * signs, length)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """The tiny agent trained by ``train_and_evaluate`` (what ``jarena train`` runs) on 16 two-mode episodes."""
    arena = jarena.build_arena(PENDULUM)
    path = str(tmp_path_factory.mktemp("demos") / "two_modes")
    actions = two_mode_demonstrations(path, arena)
    agent = jarena_agents.build_agent("diffusion", dict(TINY, dataset=path))
    result = train_and_evaluate(agent, arena, jax.random.key(0), validate_every=0, progress=False)
    # 256 arenas' first observations (the policy reads only observations, goals and step counts)
    states = np.random.default_rng(3).uniform(-1.0, 1.0, (256, 3)).astype(np.float32)
    info = infos({"state": states}, np.zeros(256, np.int32), goal_dim=0)
    policy = agent.policy(result.train_state, arena.spec)
    act = jax.jit(agent.act)
    return dict(arena=arena, path=path, agent=agent, result=result, info=info, policy=policy, act=act,
                demonstrated=np.asarray(actions), sampled=np.asarray(act(policy, info, jax.random.key(5))[0])[:, 0])


def test_training_from_a_dataset_reduces_the_loss_and_samples_both_modes(trained):
    result, sampled, demonstrated = trained["result"], trained["sampled"], trained["demonstrated"]
    assert set(np.unique(demonstrated)) == {-MODE, MODE}
    losses = [h["loss"] for h in result.history]
    assert len(losses) == 20 and losses[-1] < 0.1 * losses[0]
    assert all(h["episodes"] == 0 and math.isnan(h["episode_return"]) for h in result.history)  # no env episodes
    assert result.evaluation.episodes.size > 0  # it acted through the runners: batch_state, chunks, resets
    positive, negative = np.mean(sampled > 0.75 * MODE), np.mean(sampled < -0.75 * MODE)
    between = np.mean(np.abs(sampled) < 0.5 * MODE)
    # a Gaussian fitted to the same actions puts much of its mass between the modes; the diffusion model does not
    mean, std = demonstrated.mean(), demonstrated.std()
    gaussian = 0.5 * (math.erf((0.5 * MODE - mean) / (std * math.sqrt(2))) - math.erf((-0.5 * MODE - mean) /
                                                                                        (std * math.sqrt(2))))
    print(f"sampled: {positive:.2f} at +{MODE}, {negative:.2f} at -{MODE}, {between:.3f} between (a Gaussian fit: "
          f"{gaussian:.2f}); demonstrated: {np.mean(demonstrated > 0):.2f} at +{MODE}")
    assert positive > 0.2 and negative > 0.2 and between < 0.08 and gaussian > 0.3


@pytest.fixture(scope="module")
def cloned(tmp_path_factory):
    """The point mass oracle's 16 demonstrations, the agent trained on them, and the oracle's, random's and the
    agent's mean returns over 16 eval episodes (one key)."""
    arena = jarena.build_arena(POINT_MASS)
    path = str(tmp_path_factory.mktemp("demos") / "point_mass")
    oracle = jarena_agents.build_agent("oracle_point_mass")
    with TrajectoryDataset(path, "w", **configs_for(arena)) as dataset:
        jarena.collect(oracle, arena, dataset, 16, key=jax.random.key(1), progress=False)
    agent = jarena_agents.build_agent("diffusion", dict(CLONE, dataset=path))
    train_state, _ = jax.jit(agent.train, static_argnums=(1, 2))(agent.init_training(jax.random.key(0), arena), arena,
                                                                CLONE["total_steps"])
    policy = agent.policy(train_state, arena.spec)

    def mean_return(who, agent_state=None):
        result = jarena.evaluate(who, arena, jax.random.key(0), agent_state=agent_state, episodes=range(16))
        return float(result.summary()["return_mean"])

    return dict(agent=agent, train_state=train_state, policy=policy, diffusion=mean_return(agent, policy),
                oracle=mean_return(oracle), random=mean_return(jarena_agents.build_agent("random")))


def test_it_clones_the_point_mass_oracle(cloned):
    """Closed loop: the agent's return is far above random's and near the oracle's it learnt from."""
    oracle, random, diffusion = cloned["oracle"], cloned["random"], cloned["diffusion"]
    print(f"point mass returns: oracle {oracle:.1f}, diffusion {diffusion:.1f}, random {random:.1f}")
    assert oracle - random > 15  # reaching the goal needs the skill: the bar is not vacuous
    assert diffusion - random > 0.7 * (oracle - random)  # 0.82-0.86 measured


def test_planned_actions_follow_the_demonstrated_ones(cloned):
    """Open loop, for 256 windows of the demonstrations: the actions planned from a window's two observations (the
    acting path: history, normalisation, DDIM sampling, the executed slice) are those demonstrated after them, to
    well within the spread of the demonstrated actions."""
    agent, train_state, policy = cloned["agent"], cloned["train_state"], cloned["policy"]
    settings, count = agent.settings, 256
    observation, goal, actions = data.sample_windows(train_state.data, train_state.lengths, jax.random.key(7), count,
                                                     settings.horizon, settings.obs_horizon, settings.action_steps)

    @jax.jit
    def plan(key):
        # the arenas have seen observation 0 and used up their chunk: observation 1 makes them plan from both
        seen = jnp.concatenate([observation["state"][:, 0], goal["goal"]], axis=-1)
        memory = agent.batch_state(policy, count).memory
        memory = memory.replace(history={"vector": jnp.stack([seen, seen], axis=1), "images": {}},
                                started=jnp.ones(count, bool))
        info = infos({"state": observation["state"][:, 1]}, jnp.ones(count, jnp.int32), goal_dim=2)
        return agent.act(policy.replace(memory=memory), info.replace(goal=goal["goal"]), key)[1].memory.chunk

    first = settings.obs_horizon - 1
    demonstrated = np.asarray(actions)[:, first:first + settings.action_steps]
    error = np.abs(np.asarray(plan(jax.random.key(2))) - demonstrated).mean()
    spread = np.abs(demonstrated - demonstrated.mean((0, 1))).mean()
    print(f"planned actions: mean absolute error {error:.3f}, the demonstrated actions' spread {spread:.3f}")
    assert spread > 0.2 and error < 0.5 * spread


def test_acting_is_the_same_at_any_batch_size(trained):
    """Arena i's noise comes from the key and i alone: the first three of 256 arenas act as three arenas alone."""
    info, policy, act, sampled = trained["info"], trained["policy"], trained["act"], trained["sampled"]
    three = jax.tree_util.tree_map(lambda x: x[:3], info)
    alone, state = act(policy, three, jax.random.key(5))
    np.testing.assert_allclose(np.asarray(alone)[:, 0], sampled[:3], rtol=1e-5, atol=1e-5)
    assert state.memory.chunk.shape == (3, TINY["action_steps"], 1)
    other, _ = act(policy, three, jax.random.key(6))
    assert not np.allclose(other, alone)


def test_ddpm_sampling_keeps_the_modes_and_any_batch_size(trained):
    """``sampler: ddpm`` with all 100 steps (the paper's): the same trained weights still sample both modes and
    little between them, and arena i's noise still comes from the key and i alone."""
    agent = jarena_agents.build_agent("diffusion", dict(TINY, dataset=trained["path"], sampler="ddpm",
                                                        inference_steps=100))
    policy = agent.policy(trained["result"].train_state, trained["arena"].spec)
    act, info = jax.jit(agent.act), trained["info"]
    sampled = np.asarray(act(policy, info, jax.random.key(5))[0])[:, 0]
    assert np.mean(sampled > 0.75 * MODE) > 0.2 and np.mean(sampled < -0.75 * MODE) > 0.2
    assert np.mean(np.abs(sampled) < 0.5 * MODE) < 0.08
    assert not np.allclose(sampled, trained["sampled"])  # not the DDIM samples
    three = jax.tree_util.tree_map(lambda x: x[:3], info)
    np.testing.assert_allclose(np.asarray(act(policy, three, jax.random.key(5))[0])[:, 0], sampled[:3], rtol=1e-5,
                               atol=1e-5)
    with pytest.raises(ConfigError, match=r"sampler must be one of \['ddim', 'ddpm'\], got 'euler'"):
        jarena_agents.build_agent("diffusion", dict(TINY, sampler="euler"))


def infos(observation: dict, step: np.ndarray, goal_dim: int) -> Info:
    """Infos of (..., B) steps holding ``observation`` and ``step``, every other field zeros."""
    zeros = np.zeros(step.shape, np.float32)
    return Info(observation=observation, reward=zeros, terminated=zeros.astype(bool), truncated=zeros.astype(bool),
                success=zeros.astype(bool), goal=np.zeros(step.shape + (goal_dim,), np.float32), step=step,
                episode=np.zeros(step.shape, np.int32), fault=np.zeros(step.shape, np.int32))


def image_spec() -> ArenaSpec:
    return ArenaSpec(observation=Dict(rgb=Box(0, 255, (16, 16, 3), np.uint8), state=Box(-1.0, 1.0, (2,))),
                     action=Box(-2.0, 2.0, (2,)), name="images")


def test_the_chunk_is_replayed_for_its_steps_then_replanned():
    """Untrained: T_a = 8 of the 16 generated actions run before the next plan; a new episode or ``reset`` replans
    its arena at once. 2 DDIM steps: the bookkeeping does not depend on them."""
    agent = jarena_agents.build_agent("diffusion", dict(down_dims=(8,), groups=2, step_embedding=16,
                                                        inference_steps=2))  # horizon 16, T_o 2, T_a 8
    spec = ArenaSpec(observation=Dict(state=Box(-1.0, 1.0, (2,))), action=Box(-2.0, 2.0, (2,)), name="states")
    count, steps = 2, 11
    states = np.random.default_rng(0).uniform(-1, 1, (steps, count, 2)).astype(np.float32)
    step = np.tile(np.arange(steps, dtype=np.int32)[:, None], (1, count))
    step[5:, 1] -= 5  # arena 1 starts a new episode at t = 5
    batch = infos({"state": states}, step, goal_dim=0)

    @jax.jit
    def run(key):
        state = agent.init(key, spec, count)

        def one(state, inputs):
            t, info = inputs
            state = jax.lax.cond(t == 9, lambda s: agent.reset(s, jnp.array([True, False])), lambda s: s, state)
            action, state = agent.act(state, info, jax.random.fold_in(key, t))
            memory = state.memory
            return state, (action, memory.chunk, memory.position, memory.history["vector"])

        return jax.lax.scan(one, state, (jnp.arange(steps), batch))[1]

    actions, chunks, positions, history = (np.asarray(x) for x in run(jax.random.key(0)))
    assert actions.shape == (steps, count, 2) and np.all(np.abs(actions) <= 2.0)
    # arena 0: plans at t = 0, replays 8 steps, plans at t = 8, then again after its reset at t = 9
    np.testing.assert_array_equal(positions[:, 0], [1, 2, 3, 4, 5, 6, 7, 8, 1, 1, 2])
    np.testing.assert_array_equal(actions[:8, 0], chunks[0, 0])  # steps 0-7 are the plan made at t = 0
    assert all(np.array_equal(chunks[t, 0], chunks[0, 0]) for t in range(8))  # whatever was observed meanwhile
    assert not np.allclose(chunks[8, 0], chunks[0, 0]) and not np.allclose(chunks[9, 0], chunks[8, 0])
    # arena 1: a new episode at t = 5 replans there, and the reset of arena 0 leaves it be
    np.testing.assert_array_equal(positions[:, 1], [1, 2, 3, 4, 5, 1, 2, 3, 4, 5, 6])
    assert all(np.array_equal(chunks[t, 1], chunks[5, 1]) for t in range(5, steps))
    # the history holds the last T_o observations, oldest first, the first one repeated when an episode starts
    np.testing.assert_array_equal(history[0, 0], states[[0, 0], 0])
    np.testing.assert_array_equal(history[8, 0], states[[7, 8], 0])
    np.testing.assert_array_equal(history[5, 1], states[[5, 5], 1])
    np.testing.assert_array_equal(history[9, 0], states[[9, 9], 0])  # reset: a fresh history


def test_an_image_only_arena_traces():
    """Images and no vector (the cloth arenas' rgb): init and act trace (shapes only, nothing compiled)."""
    agent = jarena_agents.build_agent("diffusion", dict(crop=12, encoder_widths=(4,), encoder_blocks=(1,),
                                                        encoder_group_size=4, down_dims=(8,), groups=2))
    spec = ArenaSpec(observation=Dict(rgb=Box(0, 255, (16, 16, 3), np.uint8)), action=Box(-1.0, 1.0, (4,)))
    info = infos({"rgb": np.zeros((3, 16, 16, 3), np.uint8)}, np.zeros(3, np.int32), goal_dim=0)
    action, state = jax.eval_shape(lambda key: agent.act(agent.init(key, spec, 3), info, key), jax.random.key(0))
    assert action.shape == (3, 4) and state.memory.history["vector"].shape == (3, 2, 0)


def test_clear_errors(trained, tmp_path):
    arena, path = trained["arena"], trained["path"]

    def build(**config):
        return jarena_agents.build_agent("diffusion", config)

    for config, message in [
        (dict(down_dims=(12, 24)), r"each of down_dims \[12, 24\] must be a multiple of groups \(8\)"),
        (dict(horizon=10), r"horizon \(10\) must be a multiple of 4"),
        (dict(obs_horizon=4, action_steps=14), r"obs_horizon - 1 \+ action_steps .* must be at most horizon \(16\)"),
        (dict(kernel=4), "kernel must be odd"),
        (dict(inference_steps=200), r"inference_steps \(200\) must be at most diffusion_steps \(100\)"),
        (dict(total_steps=100), r"warmup_steps \(500\) must be fewer than total_steps \(100\)"),
        (dict(encoder_widths=(8, 16), encoder_blocks=(1,)), "must be lists of positive integers of one length"),
        (dict(obs_horizon=0), "'obs_horizon' of agent 'diffusion' must be >= 1"),
        (dict(crop=-3), "'crop' of agent 'diffusion' must be >= 1"),
        (dict(horizon_steps=3), r"unknown config key\(s\) \['horizon_steps'\]"),
    ]:
        with pytest.raises(ConfigError, match=message):
            build(**config)
    with pytest.raises(ConfigError, match=r"needs a bounded float Box action spec, got Discrete"):
        build().init(jax.random.key(0), jarena.build_arena("classic|domain:cartpole").spec, 1)
    with pytest.raises(ConfigError, match=r"crop=84 does not fit image 'rgb' of 16 x 16; set crop to at most 16"):
        build().init(jax.random.key(0), image_spec(), 1)
    with pytest.raises(ValueError, match="set its config key dataset=PATH"):
        build().init_training(jax.random.key(0), arena)
    with pytest.raises(DatasetError, match="no dataset at"):
        build(dataset=str(tmp_path / "none")).init_training(jax.random.key(0), arena)
    with pytest.raises(DatasetError, match="does not fit arena 'classic-point_mass-reach'"):
        build(dataset=path).init_training(jax.random.key(0), jarena.build_arena("classic|domain:point_mass"))
    with pytest.raises(DatasetError, match="needs trajectories of at least 56 steps; the longest .* has 24"):
        build(dataset=path, horizon=64).init_training(jax.random.key(0), arena)
    assert "diffusion" in jarena_agents.list_agents("imitation")
