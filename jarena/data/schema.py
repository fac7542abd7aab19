"""The self-describing schema of a trajectory dataset: observation, action and goal field configs.

Each field has a shape (per item), a dtype (kept as is: uint8 images stay uint8), an output key (the
key it gets in what the dataset returns) and an optional compression. Configs are given as in
Agent-Arena, ``{"rgb": {"shape": (64, 64, 3), "dtype": "uint8", "output_key": "rgb"}}``, or with
:class:`Field` values; the dataset saves them as JSON in the store, so reading needs no configs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

GROUPS = ("observation", "action", "goal")
# Which row index each group's arrays use: one row per observation (T + 1 per trajectory), per step (T) or
# per trajectory.
ROWS_PER = {"observation": "observation", "action": "step", "goal": "trajectory", "step": "step",
            "trajectory": "trajectory"}
COMPRESSIONS = ("zstd", "gzip", "blosc", "lz4")


class DatasetError(ValueError):
    """A bad dataset config, a mismatch between data and schema, or a corrupt store."""


@dataclasses.dataclass(frozen=True)
class Field:
    """One stored field.

    Attributes:
      shape: shape of one item (one step's observation or action, or one trajectory's goal).
      dtype: numpy dtype name (``"float32"``, ``"uint8"``, ``"int32"``, ``"bool"``...).
      output_key: the key of this field in returned data (default: the field's name).
      compression: ``None`` (raw), or a codec name from ``COMPRESSIONS``, optionally with a level,
        e.g. ``"zstd:5"``.
    """

    shape: tuple[int, ...]
    dtype: str = "float32"
    output_key: str | None = None
    compression: str | None = None

    def __post_init__(self):
        try:
            shape = tuple(int(s) for s in self.shape)
        except (TypeError, ValueError):
            raise DatasetError(f"field shape must be a tuple of ints, got {self.shape!r}") from None
        if any(s < 0 for s in shape):
            raise DatasetError(f"field shape must not be negative, got {shape}")
        try:
            dtype = np.dtype(self.dtype)
        except TypeError:
            raise DatasetError(f"unknown dtype {self.dtype!r}") from None
        if dtype.kind not in "biuf":
            raise DatasetError(f"field dtype must be bool, int, uint or float, got {dtype.name}")
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "dtype", dtype.name)
        if self.compression is not None:
            name, _, level = str(self.compression).partition(":")
            if name not in COMPRESSIONS or (level and not level.isdigit()):
                raise DatasetError(f"unknown compression {self.compression!r}; valid: None or one of "
                                   f"{list(COMPRESSIONS)}, optionally with ':level'")

    @property
    def itemsize(self) -> int:
        """Bytes per item."""
        return int(np.prod(self.shape, dtype=np.int64)) * np.dtype(self.dtype).itemsize

    def to_json(self) -> dict[str, Any]:
        return {"shape": list(self.shape), "dtype": self.dtype, "output_key": self.output_key,
                "compression": self.compression}


# Every step's own fields beside the action.
STEP_FIELDS = {"reward": Field((), "float32"), "terminated": Field((), "bool"), "truncated": Field((), "bool")}


def as_field(name: str, config: Any) -> Field:
    """A :class:`Field` from a ``Field`` or a config dict; the output key defaults to ``name``."""
    if isinstance(config, Field):
        field = config
    elif isinstance(config, Mapping):
        unknown = set(config) - {"shape", "dtype", "output_key", "compression"}
        if unknown or "shape" not in config:
            raise DatasetError(f"field {name!r}: config needs 'shape' and may have 'dtype', 'output_key', "
                               f"'compression'; got keys {sorted(config)}")
        field = Field(**config)
    else:
        raise DatasetError(f"field {name!r}: expected a Field or a dict with 'shape', got {config!r}")
    return dataclasses.replace(field, output_key=field.output_key or name)


@dataclasses.dataclass(frozen=True)
class Schema:
    """Field configs of a dataset, by group; each a ``dict[name, Field]`` sorted by name.

    Besides these fields every dataset stores, per step, ``reward`` (float32), ``terminated`` and
    ``truncated`` (bool), and per trajectory its ``length`` and ``episode`` id.
    """

    observation: dict[str, Field]
    action: dict[str, Field]
    goal: dict[str, Field] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        for group in GROUPS:
            fields = getattr(self, group) or {}
            if not isinstance(fields, Mapping):
                raise DatasetError(f"{group} config must be a dict of fields, got {type(fields).__name__}")
            fields = {str(k): as_field(str(k), v) for k, v in sorted(fields.items())}
            keys = [f.output_key for f in fields.values()]
            if len(set(keys)) != len(keys):
                raise DatasetError(f"{group} fields share an output key: {keys}")
            object.__setattr__(self, group, fields)
        for group in ("observation", "action"):
            if not getattr(self, group):
                raise DatasetError(f"the {group} config needs at least one field")

    def to_json(self) -> dict[str, Any]:
        return {group: {name: f.to_json() for name, f in getattr(self, group).items()} for group in GROUPS}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Schema:
        return cls(**{group: dict(data.get(group) or {}) for group in GROUPS})

    def differences(self, other: Schema) -> list[str]:
        """Human-readable differences from ``other`` (empty when equal)."""
        out = []
        for group in GROUPS:
            mine, theirs = getattr(self, group), getattr(other, group)
            for name in sorted(set(mine) | set(theirs)):
                if name not in theirs:
                    out.append(f"{group} field {name!r} is in the store but not in the given config")
                elif name not in mine:
                    out.append(f"{group} field {name!r} is in the given config but not in the store")
                elif mine[name] != theirs[name]:
                    out.append(f"{group} field {name!r}: store has {mine[name].to_json()}, "
                               f"given {theirs[name].to_json()}")
        return out


def spec_fields(spec: Any, default_name: str) -> dict[str, Field]:
    """Fields for the arrays described by a jarena spec (a ``Dict`` of boxes, or one ``Box``/``Discrete``)."""
    spaces = getattr(spec, "spaces", None)
    if isinstance(spaces, Mapping):
        return {name: Field(s.shape, np.dtype(s.dtype).name) for name, s in spaces.items()}
    if isinstance(spaces, tuple):
        raise DatasetError("tuple specs are not supported; give the dataset a dict of fields")
    return {default_name: Field(spec.shape, np.dtype(spec.dtype).name)}


# ---------------------------------------------------------------------------------------------- checking data
def as_fields(data: Any, fields: Mapping[str, Field], what: str, where: str) -> dict[str, np.ndarray]:
    """``data`` (a dict by field name, or one array when there is one field) as arrays by field name;
    keys not in ``fields`` are dropped. ``what`` and ``where`` name the data in errors."""
    if data is None:
        raise DatasetError(f"{where}: missing {what}; expected fields {sorted(fields)}")
    if not isinstance(data, Mapping):
        if len(fields) != 1:
            raise DatasetError(f"{where}: {what} must be a dict with fields {sorted(fields)}, got "
                               f"{type(data).__name__}")
        return {next(iter(fields)): np.asarray(data)}
    missing = sorted(set(fields) - set(data))
    if missing:
        raise DatasetError(f"{where}: {what} lacks field(s) {missing}; the schema has {sorted(fields)}, "
                           f"given {sorted(data)}")
    return {name: np.asarray(data[name]) for name in fields}


def conform(value: Any, field: Field, lead: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as an array of shape ``lead + field.shape`` and the field's dtype (converting only within a
    kind, e.g. float64 to float32); a ``DatasetError`` naming ``what`` otherwise."""
    value = np.asarray(value)
    want = lead + field.shape
    if value.shape != want:
        raise DatasetError(f"{what}: expected shape {want} ({field.shape} per item), got {value.shape}")
    if value.dtype != np.dtype(field.dtype) and not np.can_cast(value.dtype, field.dtype, casting="same_kind"):
        raise DatasetError(f"{what}: dtype {value.dtype} does not convert safely to the field's {field.dtype}")
    return value.astype(field.dtype, copy=False)
