import jax
import jax.numpy as jnp
import numpy as np
import pytest
from streams import episode_stream, item, stored

from jarena.data import BufferError, make_buffer


def _add_all(buffer, state, stream, chunk):
    add = jax.jit(buffer.add, donate_argnums=0)
    t = stream["x"].shape[0]
    for i in range(0, t, chunk):
        part = {k: v[i:i + chunk] for k, v in stream.items()}
        if chunk == 1:
            part = {k: v[0] for k, v in part.items()}
        state = add(state, part)
    return state


@pytest.mark.parametrize("bad, match", [
    (dict(capacity=10, num_arenas=3), "multiple of num_arenas=3"),
    (dict(mode="windows"), "valid modes are"),
    (dict(mode="window"), "length"),
    (dict(mode="window", length=100), "exceeds the 16 items"),
    (dict(mode="transition", length=4), "length must be None"),
    (dict(sample_batch_size=0), "sample_batch_size must be a positive int"),
    (dict(min_size=1000), "min_size=1000 exceeds capacity=64"),
])
def test_make_buffer_rejects_bad_arguments(bad, match):
    args = dict(num_arenas=4, capacity=64, sample_batch_size=8) | bad
    with pytest.raises(BufferError, match=match):
        make_buffer(**args)


def test_add_checks_shapes_dtypes_and_structure_under_jit():
    stream = episode_stream(4, 8)
    buffer = make_buffer(4, 64, 8)
    state = buffer.init(item(stream))
    add = jax.jit(buffer.add)
    one = {k: v[0] for k, v in stream.items()}
    with pytest.raises(BufferError, match=r"leaf \['x'\] has shape \(3, 2\); expected \(4, \*\(2,\)\)"):
        add(state, one | {"x": one["x"][:3]})
    with pytest.raises(BufferError, match=r"\['x'\] has dtype int32; the buffer stores float32"):
        add(state, one | {"x": one["x"].astype(np.int32)})
    with pytest.raises(BufferError, match="structure differs"):
        add(state, {k: v for k, v in one.items() if k != "x"})
    with pytest.raises(BufferError, match="1 to 16 steps per arena"):
        add(state, {k: np.concatenate([v] * 3) for k, v in stream.items()})
    with pytest.raises(BufferError, match="has no 'episode'"):
        make_buffer(4, 64, 8).init({"x": np.zeros(2, np.float32)})


def test_adding_steps_one_by_one_or_in_chunks_gives_the_same_state():
    stream = episode_stream(3, 50, seed=1)
    buffer = make_buffer(3, 60, 8)
    by_step = _add_all(buffer, buffer.init(item(stream)), stream, 1)
    by_chunk = _add_all(buffer, buffer.init(item(stream)), stream, 7)
    jax.tree_util.tree_map(np.testing.assert_array_equal, by_step, by_chunk)
    # the ring holds the newest 20 steps of every arena, oldest first from `position`
    assert int(by_step.count) == 20 and int(by_step.size) == 60
    order = (int(by_step.position) + np.arange(20)) % 20
    np.testing.assert_array_equal(np.asarray(by_step.experience["x"])[order], stored(stream, 20)["x"])


def test_run_lengths_track_episode_stretches():
    stream = episode_stream(2, 30, seed=2)
    buffer = make_buffer(2, 1000, 4)
    state = _add_all(buffer, buffer.init(item(stream)), stream, 5)
    run = np.asarray(state.run)[:30]
    expect = np.where(stream["step"] == 0, 1, 0)
    for t in range(1, 30):
        expect[t] = np.where(stream["step"][t] == 0, 1, expect[t - 1] + 1)
    np.testing.assert_array_equal(run, expect)


def test_add_updates_in_place_when_donated():
    stream = episode_stream(8, 4)
    buffer = make_buffer(8, 8 * 512, 8)
    state = buffer.init(item(stream))
    add = jax.jit(buffer.add, donate_argnums=0)
    state = add(state, {k: v[0] for k, v in stream.items()})
    pointer = state.experience["x"].unsafe_buffer_pointer()
    for t in range(1, 4):
        state = add(state, {k: v[t] for k, v in stream.items()})
    assert state.experience["x"].unsafe_buffer_pointer() == pointer
    assert add._cache_size() == 1  # no retracing


def test_can_sample_needs_min_size():
    stream = episode_stream(2, 10)
    buffer = make_buffer(2, 20, 4, min_size=6)
    state = buffer.init(item(stream))
    assert not bool(buffer.can_sample(state))
    state = _add_all(buffer, state, {k: v[:2] for k, v in stream.items()}, 1)
    assert not bool(buffer.can_sample(state))
    state = _add_all(buffer, state, {k: v[2:3] for k, v in stream.items()}, 1)
    assert bool(buffer.can_sample(state))


def test_replace_swaps_a_function():
    buffer = make_buffer(2, 20, 4)
    other = buffer.replace(sample=lambda state, key: "mine")
    assert other.sample(None, None) == "mine" and other.add is buffer.add


def test_custom_accessors():
    items = {"ep": jnp.zeros((4, 2), jnp.int32), "t": jnp.tile(jnp.arange(4)[:, None], (1, 2)),
             "end": jnp.array([[0, 0], [0, 0], [0, 0], [1, 1]], bool)}
    buffer = make_buffer(2, 8, 3, mode="trajectory", length=4, episode_of=lambda x: x["ep"],
                         step_of=lambda x: x["t"], done_of=lambda x: x["end"])
    state = jax.jit(buffer.add)(buffer.init(jax.tree_util.tree_map(lambda x: x[0, 0], items)), items)
    sample = jax.jit(buffer.sample)(state, jax.random.key(0))
    assert bool(sample.mask.all()) and sample.experience["t"].tolist() == [[0, 1, 2, 3]] * 3


@pytest.mark.parametrize("steps", [None, 3])
def test_compiled_add_never_copies_a_whole_array(steps):
    stream = episode_stream(8, 4)
    buffer = make_buffer(8, 8 * 96, 8)
    state = buffer.init(item(stream))
    batch = {k: v[0] if steps is None else v[:steps] for k, v in stream.items()}
    hlo = jax.jit(buffer.add, donate_argnums=0).lower(state, batch).compile().as_text()
    copies = [line for line in hlo.splitlines() if " copy(" in line and "[96,8" in line]
    assert not copies, copies
