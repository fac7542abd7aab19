import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jarena.core.spec import Box, Dict, Discrete, SpecError, Tuple, as_spec, spec_from_value


def test_box_sample_contains_and_bounds():
    box = Box(-1.0, [1.0, 2.0])
    assert box.shape == (2,)
    xs = jax.vmap(box.sample)(jax.random.split(jax.random.key(0), 1000))
    assert xs.shape == (1000, 2) and xs.dtype == jnp.float32
    assert bool(jnp.all(jax.vmap(box.contains)(xs)))
    assert float(xs[:, 1].max()) > 1.0  # uses the per-dimension bound
    assert not bool(box.contains(jnp.array([0.0, 2.5])))
    assert not bool(box.contains(jnp.zeros(3)))


def test_unbounded_box_samples_finite_values():
    box = Box(-np.inf, np.inf, (3,))
    assert bool(jnp.all(jnp.isfinite(box.sample(jax.random.key(1)))))
    half = Box(0.0, np.inf, (100,))
    assert bool(half.contains(half.sample(jax.random.key(2))))


def test_discrete():
    d = Discrete(3)
    xs = jax.vmap(d.sample)(jax.random.split(jax.random.key(0), 500))
    assert set(np.unique(np.asarray(xs))) == {0, 1, 2}
    assert bool(d.contains(2)) and not bool(d.contains(3)) and not bool(d.contains(jnp.array([1])))


def test_validate_raises_clear_errors():
    box = Box(-1, 1, (2,))
    with pytest.raises(SpecError, match=r"expected shape \(2,\).*got shape \(3,\)"):
        box.validate(jnp.zeros(3), "action")
    with pytest.raises(SpecError, match="expected a scalar integer in \\[0, 2\\)"):
        Discrete(2).validate(jnp.float32(1.0), "action")
    with pytest.raises(SpecError, match="expected a float array"):
        box.validate(jnp.zeros(2, bool))
    assert box.validate(jnp.zeros(2, jnp.int32)).dtype == jnp.float32  # ints are promoted


def test_validate_works_under_jit():
    box = Box(-1, 1, (2,))
    assert jax.jit(lambda x: box.validate(x))(jnp.ones(2)).shape == (2,)
    with pytest.raises(SpecError):
        jax.jit(lambda x: box.validate(x))(jnp.ones(4))


def test_dict_and_tuple_specs():
    spec = as_spec({"a": Box(0, 1, (2,)), "b": (Discrete(4), Box(-1, 1, ()))})
    assert isinstance(spec, Dict) and isinstance(spec["b"], Tuple)
    x = spec.sample(jax.random.key(0))
    assert bool(spec.contains(x))
    assert spec.validate(x)["a"].shape == (2,)
    with pytest.raises(SpecError, match=r"missing \['b'\]"):
        spec.validate({"a": jnp.zeros(2)})
    with pytest.raises(SpecError, match=r"value\['b'\]\[0\]"):
        spec.validate({"a": jnp.zeros(2), "b": (jnp.zeros(2), jnp.zeros(()))})


def test_specs_are_hashable_and_comparable():
    assert Box(-1, 1, (2,)) == Box(-1.0, 1.0, (2,))
    assert hash(Box(-1, 1, (2,))) == hash(Box(-1.0, 1.0, (2,)))
    assert Box(-1, 1, (2,)) != Box(-1, 2, (2,))
    assert len({Discrete(2), Discrete(2), Discrete(3)}) == 2
    with pytest.raises(AttributeError):
        Box(-1, 1).shape = (3,)


def test_spec_from_value_and_bad_bounds():
    s = spec_from_value({"x": jax.ShapeDtypeStruct((3,), jnp.float32)})
    assert s["x"].shape == (3,)
    with pytest.raises(SpecError, match="low > high"):
        Box(1, -1)
