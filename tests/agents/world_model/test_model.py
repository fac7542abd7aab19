"""The world model: its loss on tiny inputs, the sequence layout, resets, determinism, images, and that a tiny
model learns classic pendulum's dynamics and rewards well enough to plan over."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import jarena
import jarena.data
import jarena_agents
from jarena.data.experience import transition_from
from jarena_agents.config import ConfigError
from jarena_agents.planners.cem import CEMConfig, cem_improve
from jarena_agents.planners.sampling import rollout_returns
from jarena_agents.world_model import model as wm
from jarena_agents.world_model.networks import RSSMCell

TINY = wm.WorldModelConfig(deter=16, stoch=4, classes=4, hidden=16, layers=1, bins=255)
SMALL = wm.WorldModelConfig(deter=64, stoch=8, classes=8, hidden=64, layers=1, model_learning_rate=1e-3)


@pytest.fixture(scope="module")
def pendulum():
    return jarena.build_arena("classic|domain:pendulum")


@functools.partial(jax.jit, static_argnums=(0, 2, 3))  # one program, not op by op (slow to compile on CPU)
def random_transitions(arena, key, arenas, steps):
    """(steps, arenas) transitions of uniformly random actions."""
    state, info = jarena.batch_reset(arena, key, arenas)

    def body(carry, k):
        state, info = carry
        action = jax.vmap(arena.action_spec.sample)(jax.random.split(k, arenas))
        state, after = jarena.batch_step(arena, state, action)
        return (state, after), transition_from(info, action, after)

    return jax.lax.scan(body, (state, info), jax.random.split(jax.random.fold_in(key, 1), steps))[1]


def windows(arena, key, arenas, steps, length, count):
    buffer = jarena.data.make_buffer(num_arenas=arenas, capacity=arenas * steps, sample_batch_size=count,
                                     mode="window", length=length)
    fill = jax.jit(lambda key: buffer.add(buffer.init(jarena.data.experience_spec(arena)),
                                          random_transitions(arena, key, arenas, steps)))
    return buffer, fill(key)


def init_params(model, key):
    """The model's parameters, initialised as one program (op by op, flax's initialisers compile hundreds)."""
    return jax.jit(lambda key: wm.init_params(model, key))(key)


def test_sequences_from_windows_lay_out_steps(pendulum):
    transitions = random_transitions(pendulum, jax.random.key(0), 2, 3)
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), transitions)  # (B=2, L=3)
    seq = jax.jit(lambda e: wm.sequences_from_windows(pendulum.spec, e))(experience)
    assert seq.vector.shape == (2, 4, 3) and seq.action.shape == (2, 4, 1)
    np.testing.assert_array_equal(seq.vector[:, 0], experience.observation["state"][:, 0])
    np.testing.assert_array_equal(seq.vector[:, 1:], experience.next_observation["state"])
    np.testing.assert_array_equal(seq.action[:, 0], 0.0)
    np.testing.assert_array_equal(seq.action[:, 1:], experience.action)
    np.testing.assert_array_equal(seq.reward[:, 1:], experience.reward)
    np.testing.assert_array_equal(seq.is_first, [[True, False, False, False]] * 2)
    np.testing.assert_array_equal(seq.mask, [[0, 1, 1, 1]] * 2)
    np.testing.assert_array_equal(seq.cont, 1.0)


def test_loss_at_initialisation_matches_hand_values(pendulum):
    """The zero-initialised reward head predicts a uniform two-hot: its loss is log(255) whatever the rewards;
    the KL terms never fall below the free nats; the total is the weighted sum of the terms."""
    model = wm.make_world_model(pendulum.spec, TINY)
    params = init_params(model, jax.random.key(0))
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1),
                                        random_transitions(pendulum, jax.random.key(1), 3, 5))

    @jax.jit
    def loss(params, experience, key):
        seq = wm.sequences_from_windows(pendulum.spec, experience)
        total, (metrics, latents) = wm.loss(model, params, seq, key)
        return total, metrics, latents, wm.predict_reward(model, params, latents)

    total, metrics, latents, predicted = loss(params, experience, jax.random.key(2))
    np.testing.assert_allclose(metrics["reward_loss"], np.log(255), rtol=1e-5)
    assert metrics["dyn_loss"] >= 1.0 and metrics["rep_loss"] >= 1.0
    expected = (metrics["observation_loss"] + metrics["reward_loss"] + metrics["continue_loss"]
                + 0.5 * metrics["dyn_loss"] + 0.1 * metrics["rep_loss"])
    np.testing.assert_allclose(total, expected, rtol=1e-6)
    np.testing.assert_allclose(predicted, 0.0, atol=1e-5)
    assert latents.deter.shape == (3, 6, 16) and latents.stoch.shape == (3, 6, 4, 4)


def test_observing_restarts_where_is_first(pendulum):
    """A sequence flagged ``is_first`` at step 3 gives, from there on, the latents of that tail observed alone."""
    model = wm.make_world_model(pendulum.spec, TINY)
    params = init_params(model, jax.random.key(0))
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1),
                                        random_transitions(pendulum, jax.random.key(1), 2, 7))

    @jax.jit
    def whole_and_tail(params, experience):
        seq = wm.sequences_from_windows(pendulum.spec, experience)
        seq = seq.replace(is_first=seq.is_first.at[:, 3].set(True))
        whole, _, _ = wm.observe(model, params, seq, None)
        tail, _, _ = wm.observe(model, params, jax.tree_util.tree_map(lambda x: x[:, 3:], seq), None)
        return whole, tail

    whole, tail = whole_and_tail(params, experience)
    np.testing.assert_allclose(whole.deter[:, 3:], tail.deter, atol=1e-6)
    np.testing.assert_allclose(whole.stoch[:, 3:], tail.stoch, atol=1e-6)


def test_observing_a_sequence_gives_the_cells_step_by_step_posteriors_and_priors(pendulum):
    """``observe`` runs the posterior in its loop and the prior on all steps after it: the same as ``obs_step``."""
    model = wm.make_world_model(pendulum.spec, TINY)
    params = init_params(model, jax.random.key(0))
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1),
                                        random_transitions(pendulum, jax.random.key(1), 2, 4))

    @jax.jit
    def sequence_and_steps(params, experience):
        seq = wm.sequences_from_windows(pendulum.spec, experience)
        observed = wm.observe(model, params, seq, jax.random.key(2))
        embed = model.encoder.apply(params["encoder"], seq.vector, seq.images)
        latent, stepped = model.initial((2,)), []
        for t, key in enumerate(jax.random.split(jax.random.key(2), seq.reward.shape[1])):
            latent, posterior, prior = model.rssm.apply(params["rssm"], latent, seq.action[:, t], embed[:, t], key,
                                                        method=RSSMCell.obs_step)
            stepped.append((latent.stoch, posterior, prior))
        return observed, jax.tree_util.tree_map(lambda *xs: jnp.stack(xs, 1), *stepped)

    (latents, posterior, prior), (stoch, step_posterior, step_prior) = sequence_and_steps(params, experience)
    np.testing.assert_allclose(latents.stoch, stoch, atol=1e-6)
    np.testing.assert_allclose(posterior, step_posterior, atol=1e-6)
    np.testing.assert_allclose(prior, step_prior, atol=1e-6)


def test_same_key_same_result_on_any_batch_size(pendulum):
    model = wm.make_world_model(pendulum.spec, TINY)
    params = init_params(model, jax.random.key(0))
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1),
                                        random_transitions(pendulum, jax.random.key(1), 4, 5))
    seq = jax.jit(lambda e: wm.sequences_from_windows(pendulum.spec, e))(experience)
    observe = jax.jit(lambda p, s: wm.observe(model, p, s, None)[0])
    whole = observe(params, seq)
    one = observe(params, jax.tree_util.tree_map(lambda x: x[2:3], seq))
    np.testing.assert_allclose(whole.deter[2:3], one.deter, atol=1e-5)
    step = jax.jit(lambda p, s, k: wm.loss(model, p, s, k)[0])
    assert step(params, seq, jax.random.key(3)) == step(params, seq, jax.random.key(3))


def test_unrolled_scans_compute_the_same_loss_and_latents(pendulum):
    """``scan_unroll`` (3 over 7 steps: a remainder too) changes the loop, not the result: observed latents,
    imagined latents and the loss agree with the rolled scans."""
    rolled = wm.make_world_model(pendulum.spec, TINY)
    unrolled = wm.make_world_model(pendulum.spec, dataclasses.replace(TINY, scan_unroll=3))
    params = init_params(rolled, jax.random.key(0))
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1),
                                        random_transitions(pendulum, jax.random.key(1), 2, 7))

    @functools.partial(jax.jit, static_argnums=0)
    def outputs(model, params, experience):
        seq = wm.sequences_from_windows(pendulum.spec, experience)
        seq = seq.replace(is_first=seq.is_first.at[:, 3].set(True))
        latents, _, _ = wm.observe(model, params, seq, jax.random.key(2))
        start = jax.tree_util.tree_map(lambda x: x[:, -1], latents)
        imagined = wm.imagine(model, params, start, seq.action, jax.random.key(3))
        return latents, imagined, wm.loss(model, params, seq, jax.random.key(4))[0]

    for a, b in zip(jax.tree_util.tree_leaves(outputs(rolled, params, experience)),
                    jax.tree_util.tree_leaves(outputs(unrolled, params, experience)), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("dtype", ["float32", "bfloat16"])
def test_images_are_encoded_and_decoded(dtype):
    arena = jarena.build_arena("dmc|domain:cartpole,task:swingup,pixels:16,state:false")
    config = wm.WorldModelConfig(deter=8, stoch=2, classes=2, hidden=8, layers=1, cnn_depth=2, cnn_layers=2, bins=5,
                                 compute_dtype=dtype)
    model = wm.make_world_model(arena.spec, config)
    assert model.images == ("pixels",) and model.vector_size == 0
    vector, images = jax.jit(lambda key: wm.decode(model, wm.init_params(model, key), model.initial((3,))))(
        jax.random.key(0))
    assert vector is None and images["pixels"].shape == (3, 16, 16, 3) and images["pixels"].dtype == jnp.float32
    with pytest.raises(ConfigError, match="sides must divide by 32"):
        wm.make_world_model(arena.spec, wm.WorldModelConfig(cnn_layers=5))


def test_a_tiny_model_learns_pendulum_well_enough_to_plan(pendulum):
    """Trained on random-action windows, the model predicts 16 steps open loop (from 8 observed) on episodes it
    never saw at under half the error of holding the last observation, and the reward at under a third; CEM
    over the learned model (the planners' seam) finds plans the model rates above random ones."""
    buffer, data = windows(pendulum, jax.random.key(0), 32, 200, 32, 16)
    _, held_out = windows(pendulum, jax.random.key(1), 32, 200, 24, 64)
    test_buffer = jarena.data.make_buffer(num_arenas=32, capacity=32 * 200, sample_batch_size=64, mode="window",
                                          length=24)
    model = wm.make_world_model(pendulum.spec, SMALL)
    optimizer = wm.model_optimizer(SMALL)
    params = init_params(model, jax.random.key(2))

    @jax.jit
    def train(params, opt_state, key):
        def body(carry, key):
            params, opt_state = carry
            k1, k2 = jax.random.split(key)
            seq = wm.sequences_from_windows(pendulum.spec, buffer.sample(data, k1).experience)
            params, opt_state, metrics = wm.train_step(model, optimizer, params, opt_state, seq, k2)
            return (params, opt_state), metrics["model_loss"]

        # 750 updates: with every key offset by 0, 100 or 200, open-loop error / hold 0.19, 0.24, 0.14 and reward
        # error / hold 0.18, 0.20, 0.17 (1,000 updates, offset 0 and 200: 0.17, 0.19 and 0.19, 0.20)
        return jax.lax.scan(body, (params, opt_state), jax.random.split(key, 750))

    (params, _), losses = train(params, optimizer.init(params), jax.random.key(3))
    assert losses[-100:].mean() < 0.5 * losses[:10].mean()

    cfg = CEMConfig(samples=64, horizon=10, iterations=3)

    @jax.jit  # the checks below as one program: op by op they compile hundreds
    def open_loop_and_plans(params):
        seq = wm.sequences_from_windows(pendulum.spec, test_buffer.sample(held_out, jax.random.key(4)).experience)
        context = jax.tree_util.tree_map(lambda x: x[:, :8], seq)
        latents, _, _ = wm.observe(model, params, context, None)
        start = jax.tree_util.tree_map(lambda x: x[:, -1], latents)
        imagined = wm.imagine(model, params, start, seq.action[:, 8:], None)
        vector, _ = wm.decode(model, params, imagined)
        errors = dict(error=jnp.mean(jnp.abs(vector - seq.vector[:, 8:])),
                      hold=jnp.mean(jnp.abs(seq.vector[:, 7:8] - seq.vector[:, 8:])),
                      reward_error=jnp.mean(jnp.abs(wm.predict_reward(model, params, imagined) - seq.reward[:, 8:])),
                      reward_hold=jnp.mean(jnp.abs(seq.reward[:, 7:8] - seq.reward[:, 8:])))
        learned = wm.latent_model(model, params)
        one = jax.tree_util.tree_map(lambda x: x[0], start)
        plan = cem_improve(learned, cfg)(one, jnp.zeros((10, 1)), jax.random.key(5))
        random_plans = jax.random.uniform(jax.random.key(6), (64, 10, 1), minval=-2.0, maxval=2.0)
        return errors, plan, rollout_returns(learned, one, plan[None])[0], rollout_returns(learned, one, random_plans)

    errors, plan, planned, random_returns = open_loop_and_plans(params)
    error, hold = float(errors["error"]), float(errors["hold"])
    assert error < 0.5 * hold, (error, hold)
    reward_error, reward_hold = float(errors["reward_error"]), float(errors["reward_hold"])
    assert reward_error < reward_hold / 3, (reward_error, reward_hold)
    assert plan.shape == (10, 1) and bool(jnp.all(jnp.abs(plan) <= 2.0))
    assert planned > jnp.mean(random_returns)


def test_a_model_trains_offline_from_a_collected_dataset(pendulum, tmp_path):
    """Agent-Arena's PlaNet trains from collected data: windows read from a zarr TrajectoryDataset (written by
    ``collect``) become the same model inputs as the buffer's, and the model learns from them alone."""
    with jarena.data.TrajectoryDataset(tmp_path / "pendulum", "w", **jarena.data.configs_for(pendulum)) as dataset:
        jarena.data.collect(jarena_agents.build_agent("random"), pendulum, dataset, 16, key=jax.random.key(0),
                            progress=False)
    with jarena.data.TrajectoryDataset(tmp_path / "pendulum", "r") as dataset:
        loader = dataset.loader(16, mode="window", length=32)
        batch = loader.sample(jax.random.key(1))
        seq = wm.sequences_from_dataset(pendulum.spec, batch)
        # the layout: the window's first observation, then each step's next observation and the action into it
        trajectory = dataset.get_trajectory(int(batch["trajectory"][0, 0]))
        start = int(batch["step"][0, 0])
        np.testing.assert_allclose(seq.vector[0], trajectory["observation"]["state"][start:start + 33], rtol=1e-6)
        actions = trajectory["action"]["action"][start:start + 32]
        np.testing.assert_allclose(seq.action[0, 1:, 0], actions.reshape(-1), rtol=1e-6)
        np.testing.assert_allclose(seq.reward[0, 1:], trajectory["reward"][start:start + 32], rtol=1e-6)

        model = wm.make_world_model(pendulum.spec, SMALL)
        optimizer = wm.model_optimizer(SMALL)
        params = init_params(model, jax.random.key(2))
        opt_state = jax.jit(optimizer.init)(params)
        step = jax.jit(lambda p, o, b, k: wm.train_step(model, optimizer, p, o, wm.sequences_from_dataset(
            pendulum.spec, b), k))
        first = None
        for i, batch in enumerate(loader.batches(jax.random.key(3), 300)):
            params, opt_state, metrics = step(params, opt_state, batch, jax.random.key(i))
            first = float(metrics["observation_loss"]) if first is None else first
    assert float(metrics["observation_loss"]) < 0.1 * first, (first, float(metrics["observation_loss"]))


def test_flat_global_norm_clip_equals_optax_per_leaf_clip():
    # the world model's and Dreamer's clip: one norm over all leaves concatenated, the same updates as optax's
    tree = {"w": jnp.arange(12.0).reshape(3, 4) - 5.0, "b": jnp.array([3.0]), "c": {"s": jnp.array(-2.0)}}
    for max_norm in (1.0, 5.0, 1e3):  # clipped, clipped, untouched
        ours, _ = wm.clip_by_flat_global_norm(max_norm).update(tree, optax.EmptyState())
        theirs, _ = optax.clip_by_global_norm(max_norm).update(tree, optax.EmptyState())
        for a, b in zip(jax.tree_util.tree_leaves(ours), jax.tree_util.tree_leaves(theirs), strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-6)
        assert float(optax.global_norm(ours)) == pytest.approx(min(max_norm, float(optax.global_norm(tree))), rel=1e-6)


def test_bfloat16_compute_keeps_float32_params_state_and_losses(pendulum):
    """compute_dtype bfloat16 (DreamerV3's precision): the same float32 parameters, a float32 latent state, and
    losses within bfloat16's rounding of float32's on the same inputs; a gradient step keeps everything finite."""
    experience = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1),
                                        random_transitions(pendulum, jax.random.key(1), 4, 8))
    results = {}
    for dtype in ("float32", "bfloat16"):
        model = wm.make_world_model(pendulum.spec, dataclasses.replace(SMALL, compute_dtype=dtype))
        params = init_params(model, jax.random.key(0))
        optimizer = wm.model_optimizer(model.config)

        @jax.jit
        def step(params, experience, key, model=model, optimizer=optimizer):
            seq = wm.sequences_from_windows(pendulum.spec, experience)
            total, (metrics, latents) = wm.loss(model, params, seq, key)
            new, _, after, _ = wm.gradient_step(model, optimizer, params, optimizer.init(params), seq, key)
            return total, metrics, latents, new, after

        results[dtype] = (params, *step(params, experience, jax.random.key(2)))
    (p32, total32, m32, lat32, _, _), (p16, total16, m16, lat16, new16, after16) = results.values()
    same = jax.tree_util.tree_map(lambda a, b: bool(jnp.array_equal(a, b)), p32, p16)
    assert all(jax.tree_util.tree_leaves(same))  # identical float32 initial parameters
    assert lat16.deter.dtype == jnp.float32 and lat16.stoch.dtype == jnp.float32
    np.testing.assert_allclose(m16["reward_loss"], np.log(255), rtol=1e-5)  # zero-initialised head, any dtype
    np.testing.assert_allclose(m16["observation_loss"], m32["observation_loss"], rtol=0.05)
    np.testing.assert_allclose(total16, total32, rtol=0.05)
    assert all(leaf.dtype == jnp.float32 and bool(jnp.all(jnp.isfinite(leaf)))
               for leaf in jax.tree_util.tree_leaves(new16))
    assert np.isfinite(float(after16["model_loss"])) and float(after16["grad_norm"]) > 0


def test_an_unknown_compute_dtype_is_refused_naming_the_choices(pendulum):
    with pytest.raises(ConfigError, match=r"compute_dtype.*\['float32', 'bfloat16'\].*'float16'"):
        wm.make_world_model(pendulum.spec, dataclasses.replace(SMALL, compute_dtype="float16"))
    with pytest.raises(ConfigError, match="compute_dtype"):
        jarena_agents.build_agent("dreamer", {"compute_dtype": "half"})
