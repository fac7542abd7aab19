"""Specs: the shape, dtype and bounds of observations and actions.

Specs are small immutable, hashable objects (so they can be static arguments under ``jit``):

- :class:`Box` -- a real- or integer-valued array in ``[low, high]`` (bounds broadcast to ``shape``);
- :class:`Discrete` -- a scalar integer in ``{0, ..., n - 1}``;
- :class:`Dict` and :class:`Tuple` -- nested specs, mirroring dict and tuple pytrees.

Every spec has ``sample(key)``, ``contains(x)`` (a traceable boolean), ``zeros()`` and ``validate(x)``,
which checks shape and dtype *statically* (works under ``jit``) and raises a ``SpecError`` naming the
offending path and what was expected. Plain dicts and tuples of specs are accepted wherever a spec is,
through :func:`as_spec`.

``validate`` also checks *values* where it can: when ``x`` is concrete (not a ``jax`` tracer, i.e. given
eagerly), a :class:`Discrete` value must lie in ``[0, n)`` and every element of a float :class:`Box` must be
finite (NaN or inf raise a ``SpecError``). Under ``jit`` or ``vmap`` values are unknown and not checked.
Box values outside ``[low, high]`` are never an error: dynamics clip their controls, as Gymnasium's do.

Dtype rule of ``validate``: values are returned cast to the spec's dtype. An integer array into a float
Box converts as ``x.astype(dtype)`` does (exact up to 2^24 in magnitude for float32); a float into an
integer spec (Discrete or int Box) and a bool into a non-bool spec (or the reverse) are refused.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np


class SpecError(ValueError):
    """An array does not match its spec (shape, dtype, structure, or a concrete value out of range)."""


def _kind(dtype) -> str:
    dtype = np.dtype(dtype)
    if np.issubdtype(dtype, np.floating):
        return "float"
    if np.issubdtype(dtype, np.integer):
        return "int"
    if np.issubdtype(dtype, np.bool_):
        return "bool"
    raise SpecError(f"unsupported dtype {dtype}; specs hold float, int or bool arrays")


def _describe(x) -> str:
    return f"shape {tuple(np.shape(x))} and dtype {jnp.result_type(x)}"


def _concrete(x: jax.Array) -> bool:
    """Whether ``x``'s values are known now (eager), not a tracer under ``jit``, ``vmap`` or ``grad``."""
    return not isinstance(x, jax.core.Tracer)


class Spec:
    """Base class; subclasses implement the methods below."""

    def sample(self, key: jax.Array) -> Any:  # pragma: no cover - interface
        raise NotImplementedError

    def contains(self, x: Any) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def zeros(self) -> Any:  # pragma: no cover - interface
        raise NotImplementedError

    def validate(self, x: Any, name: str = "value") -> Any:  # pragma: no cover - interface
        raise NotImplementedError


class Box(Spec):
    """An array of ``shape`` and ``dtype`` with elementwise bounds ``low <= x <= high``.

    Bounds may be scalars or arrays broadcastable to ``shape``; infinite bounds are allowed (sampling
    then draws from a standard normal on unbounded sides).
    """

    __slots__ = ("low", "high", "shape", "dtype")

    def __init__(self, low, high, shape: tuple[int, ...] | None = None, dtype=jnp.float32):
        low_a, high_a = np.asarray(low), np.asarray(high)
        if shape is None:
            shape = np.broadcast_shapes(low_a.shape, high_a.shape)
        shape = tuple(int(s) for s in shape)
        dtype = np.dtype(jnp.dtype(dtype))
        _kind(dtype)
        try:
            low_a = np.broadcast_to(low_a, shape).astype(np.float64 if _kind(dtype) == "float" else np.int64)
            high_a = np.broadcast_to(high_a, shape).astype(low_a.dtype)
        except ValueError as e:
            raise SpecError(f"Box bounds of shapes {np.shape(low)} and {np.shape(high)} "
                            f"do not broadcast to shape {shape}") from e
        if np.any(low_a > high_a):
            raise SpecError(f"Box has low > high: low={low_a}, high={high_a}")
        low_a.setflags(write=False)
        high_a.setflags(write=False)
        object.__setattr__(self, "low", low_a)
        object.__setattr__(self, "high", high_a)
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "dtype", dtype)

    def __setattr__(self, name, value):
        raise AttributeError("Box is immutable")

    def __eq__(self, other):
        return (isinstance(other, Box) and self.shape == other.shape and self.dtype == other.dtype
                and np.array_equal(self.low, other.low) and np.array_equal(self.high, other.high))

    def __hash__(self):
        return hash((self.shape, str(self.dtype), self.low.tobytes(), self.high.tobytes()))

    def __repr__(self):
        lo = self.low.flat[0] if self.low.size and np.all(self.low == self.low.flat[0]) else self.low
        hi = self.high.flat[0] if self.high.size and np.all(self.high == self.high.flat[0]) else self.high
        return f"Box(low={lo}, high={hi}, shape={self.shape}, dtype={self.dtype.name})"

    @property
    def bounded(self) -> bool:
        return bool(np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high)))

    def sample(self, key):
        if _kind(self.dtype) == "int":
            return jax.random.randint(key, self.shape, self.low, self.high + 1, dtype=self.dtype)
        if _kind(self.dtype) == "bool":
            return jax.random.bernoulli(key, 0.5, self.shape)
        low, high = jnp.asarray(self.low, self.dtype), jnp.asarray(self.high, self.dtype)
        if self.bounded:
            return jax.random.uniform(key, self.shape, self.dtype, low, high)
        normal = jax.random.normal(key, self.shape, self.dtype)
        uniform = jax.random.uniform(key, self.shape, self.dtype, jnp.where(jnp.isfinite(low), low, 0.0),
                                     jnp.where(jnp.isfinite(high), high, 1.0))
        # Bounded on both sides: uniform; on one side: a shifted exponential-like draw; else normal.
        both = jnp.isfinite(low) & jnp.isfinite(high)
        only_low = jnp.isfinite(low) & ~jnp.isfinite(high)
        only_high = ~jnp.isfinite(low) & jnp.isfinite(high)
        return jnp.where(both, uniform, jnp.where(only_low, low + jnp.abs(normal),
                                                  jnp.where(only_high, high - jnp.abs(normal), normal)))

    def contains(self, x):
        x = jnp.asarray(x)
        if x.shape != self.shape:
            return jnp.asarray(False)
        low, high = jnp.asarray(self.low, x.dtype), jnp.asarray(self.high, x.dtype)
        return jnp.all((x >= low) & (x <= high))

    def zeros(self):
        return jnp.clip(jnp.zeros(self.shape, self.dtype), jnp.asarray(self.low, self.dtype),
                        jnp.asarray(self.high, self.dtype))

    def validate(self, x, name="value"):
        """Checks ``x`` and returns it cast to the spec's dtype.

        Shape and dtype kind are checked statically (also under ``jit``): an int array into a float Box
        is converted as ``x.astype(dtype)`` does; a float into an int Box and bools into a non-bool Box
        are refused. When ``x`` is concrete, every element of a float Box must be finite (NaN and inf
        raise). Values outside ``[low, high]`` are accepted: dynamics clip them, as Gymnasium's do.
        """
        if isinstance(x, Mapping | tuple | list):
            raise SpecError(f"{name}: expected an array of shape {self.shape} and dtype {self.dtype.name}, "
                            f"got a {type(x).__name__}")
        x = jnp.asarray(x)
        if x.shape != self.shape:
            raise SpecError(f"{name}: expected shape {self.shape} and dtype {self.dtype.name} "
                            f"({self!r}), got {_describe(x)}")
        want, got = _kind(self.dtype), _kind(x.dtype)
        if want != got and not (want == "float" and got == "int"):
            raise SpecError(f"{name}: expected a {want} array of dtype {self.dtype.name}, got {_describe(x)}")
        x = x.astype(self.dtype)
        if want == "float" and _concrete(x) and not np.all(np.isfinite(np.asarray(x))):
            raise SpecError(f"{name}: non-finite values (NaN or inf) in {np.asarray(x)}; expected finite "
                            f"values of {self!r} (values outside the bounds are clipped)")
        return x


class Discrete(Spec):
    """A scalar integer action or observation in ``{0, ..., n - 1}``."""

    __slots__ = ("n", "dtype")

    def __init__(self, n: int, dtype=jnp.int32):
        if int(n) < 1:
            raise SpecError(f"Discrete needs n >= 1, got {n}")
        object.__setattr__(self, "n", int(n))
        object.__setattr__(self, "dtype", np.dtype(jnp.dtype(dtype)))

    def __setattr__(self, name, value):
        raise AttributeError("Discrete is immutable")

    shape = ()

    def __eq__(self, other):
        return isinstance(other, Discrete) and self.n == other.n and self.dtype == other.dtype

    def __hash__(self):
        return hash(("Discrete", self.n, str(self.dtype)))

    def __repr__(self):
        return f"Discrete({self.n})"

    def sample(self, key):
        return jax.random.randint(key, (), 0, self.n, dtype=self.dtype)

    def contains(self, x):
        x = jnp.asarray(x)
        if x.shape != () or _kind(x.dtype) != "int":
            return jnp.asarray(False)
        return (x >= 0) & (x < self.n)

    def zeros(self):
        return jnp.zeros((), self.dtype)

    def validate(self, x, name="value"):
        """Checks that ``x`` is a scalar integer (statically) and, when concrete, in ``[0, n)``; returns it
        cast to the spec's dtype. Floats and bools are refused."""
        if isinstance(x, Mapping | tuple | list):
            raise SpecError(f"{name}: expected a scalar integer in [0, {self.n}), got a {type(x).__name__}")
        x = jnp.asarray(x)
        if x.shape != () or _kind(x.dtype) != "int":
            raise SpecError(f"{name}: expected a scalar integer in [0, {self.n}) (Discrete({self.n})), "
                            f"got {_describe(x)}")
        if _concrete(x) and not 0 <= int(x) < self.n:
            raise SpecError(f"{name}: {int(x)} is out of range; expected a scalar integer in [0, {self.n}) "
                            f"(Discrete({self.n}))")
        return x.astype(self.dtype)


class Dict(Spec):
    """A dict of specs; values are dicts of arrays with the same keys."""

    __slots__ = ("spaces",)

    def __init__(self, spaces: Mapping[str, Any] | None = None, **kwargs):
        spaces = dict(spaces or {}, **kwargs)
        object.__setattr__(self, "spaces", {k: as_spec(v) for k, v in sorted(spaces.items())})

    def __setattr__(self, name, value):
        raise AttributeError("Dict is immutable")

    def __getitem__(self, key):
        return self.spaces[key]

    def __eq__(self, other):
        return isinstance(other, Dict) and self.spaces == other.spaces

    def __hash__(self):
        return hash(tuple(self.spaces.items()))

    def __repr__(self):
        return "Dict(" + ", ".join(f"{k}={v!r}" for k, v in self.spaces.items()) + ")"

    def sample(self, key):
        keys = jax.random.split(key, max(len(self.spaces), 1))
        return {k: s.sample(kk) for (k, s), kk in zip(self.spaces.items(), keys, strict=False)}

    def contains(self, x):
        if not isinstance(x, Mapping) or set(x) != set(self.spaces):
            return jnp.asarray(False)
        return jnp.all(jnp.stack([s.contains(x[k]) for k, s in self.spaces.items()] or [jnp.asarray(True)]))

    def zeros(self):
        return {k: s.zeros() for k, s in self.spaces.items()}

    def validate(self, x, name="value"):
        if not isinstance(x, Mapping):
            raise SpecError(f"{name}: expected a dict with keys {sorted(self.spaces)}, got {type(x).__name__}")
        missing, extra = set(self.spaces) - set(x), set(x) - set(self.spaces)
        if missing or extra:
            raise SpecError(f"{name}: expected keys {sorted(self.spaces)}; missing {sorted(missing)}, "
                            f"unexpected {sorted(extra)}")
        return {k: s.validate(x[k], f"{name}[{k!r}]") for k, s in self.spaces.items()}


class Tuple(Spec):
    """A tuple of specs; values are tuples of arrays of the same length."""

    __slots__ = ("spaces",)

    def __init__(self, spaces):
        object.__setattr__(self, "spaces", tuple(as_spec(s) for s in spaces))

    def __setattr__(self, name, value):
        raise AttributeError("Tuple is immutable")

    def __getitem__(self, i):
        return self.spaces[i]

    def __eq__(self, other):
        return isinstance(other, Tuple) and self.spaces == other.spaces

    def __hash__(self):
        return hash(self.spaces)

    def __repr__(self):
        return "Tuple(" + ", ".join(map(repr, self.spaces)) + ")"

    def sample(self, key):
        keys = jax.random.split(key, max(len(self.spaces), 1))
        return tuple(s.sample(k) for s, k in zip(self.spaces, keys, strict=False))

    def contains(self, x):
        if not isinstance(x, tuple | list) or len(x) != len(self.spaces):
            return jnp.asarray(False)
        return jnp.all(jnp.stack([s.contains(v) for s, v in zip(self.spaces, x, strict=True)]
                                 or [jnp.asarray(True)]))

    def zeros(self):
        return tuple(s.zeros() for s in self.spaces)

    def validate(self, x, name="value"):
        if not isinstance(x, tuple | list) or len(x) != len(self.spaces):
            raise SpecError(f"{name}: expected a tuple of {len(self.spaces)} arrays, got {type(x).__name__}"
                            + (f" of length {len(x)}" if isinstance(x, tuple | list) else ""))
        return tuple(s.validate(v, f"{name}[{i}]") for i, (s, v) in enumerate(zip(self.spaces, x, strict=True)))


def as_spec(spec: Any) -> Spec:
    """Returns ``spec`` as a :class:`Spec`, converting plain dicts and tuples of specs."""
    if isinstance(spec, Spec):
        return spec
    if isinstance(spec, Mapping):
        return Dict(spec)
    if isinstance(spec, tuple | list):
        return Tuple(spec)
    raise SpecError(f"expected a Spec (Box, Discrete, Dict, Tuple) or a dict/tuple of them, got {spec!r}")


def spec_from_value(x: Any) -> Spec:
    """An unbounded spec with the structure, shapes and dtypes of ``x`` (arrays or ShapeDtypeStructs)."""
    if isinstance(x, Mapping):
        return Dict({k: spec_from_value(v) for k, v in x.items()})
    if isinstance(x, tuple | list):
        return Tuple([spec_from_value(v) for v in x])
    kind = _kind(x.dtype)
    if kind == "float":
        return Box(-np.inf, np.inf, x.shape, x.dtype)
    if kind == "int":
        info = np.iinfo(x.dtype)
        return Box(info.min, info.max, x.shape, x.dtype)
    return Box(0, 1, x.shape, x.dtype)


def image_spec(height: int, width: int, channels: int = 3) -> Box:
    """The spec of a camera image: ``Box(0, 255, (height, width, channels), uint8)``, shared by every camera
    sensor (the cloth's top-down camera, MJX arenas' cameras) so that image agents fit all of them."""
    for name, value in (("height", height), ("width", width), ("channels", channels)):
        if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 1:
            raise ValueError(f"image {name} must be a positive integer, got {value!r}")
    return Box(0, 255, (int(height), int(width), int(channels)), jnp.uint8)
