"""``TrajectoryDataset``: trajectories in a self-describing zarr (v3) store; crash-safe appends and resume.

Layout of the store (a zarr group in the directory ``path``)::

    observation/<name>   (sum of (T_i + 1), *shape)   each trajectory's T + 1 observations
    action/<name>        (sum of T_i, *shape)         its T actions
    goal/<name>          (num_trajectories, *shape)   its goal
    step/reward, step/terminated, step/truncated      (sum of T_i,) float32, bool, bool
    trajectory/length, trajectory/episode             (num_trajectories,) int64

    commit                                            (2,) int64: num_trajectories, num_steps

The group's attributes hold the schema (``jarena_dataset``: field configs as JSON); ``commit`` says how
many trajectories and steps are visible. Arrays grow geometrically and may hold rows past the commit;
those are invisible. A write puts all of a trajectory's rows first, then replaces the commit. Rows are
only appended past the committed ones, never over them: :mod:`jarena.data.chunks` writes new rows into
a raw chunk in place past its committed bytes, and new chunk files (and the commit) to a temporary
file moved into place with ``os.replace``; zarr (>= 3.1.3) rewrites compressed chunks the same way. So
killing the writer loses at most the trajectories being written, and ``mode="a"`` resumes after them,
writing over what they left. Chunk files sit side by side (``c.7.0.0``).
"""

from __future__ import annotations

import os
import shutil
import uuid
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import zarr
from zarr import codecs

from jarena.data.chunks import read_rows, write_rows
from jarena.data.files import lock, remove_partial_files
from jarena.data.loader import Loader
from jarena.data.schema import GROUPS, ROWS_PER, STEP_FIELDS, DatasetError, Field, Schema, as_fields, conform

FORMAT = 1
MAX_CHUNK_ROWS = 16384
MODES = ("r", "a", "w")
SCHEMA_ATTR, COMMIT = "jarena_dataset", "commit"
TRAJECTORY_FIELDS = {"length": Field((), "int64"), "episode": Field((), "int64")}
_ARGUMENT = {"observation": "observations", "action": "actions", "goal": "goal"}


def _compressors(field: Field):
    if field.compression is None:
        return None
    name, _, level = field.compression.partition(":")
    level = int(level) if level else None
    if name == "zstd":
        return [codecs.ZstdCodec(level=3 if level is None else level)]
    if name == "gzip":
        return [codecs.GzipCodec(level=5 if level is None else level)]
    cname = "zstd" if name == "blosc" else "lz4"
    return [codecs.BloscCodec(cname=cname, clevel=5 if level is None else level, shuffle="shuffle")]


def _fields(schema: Schema) -> dict[str, Field]:
    """Every stored array of ``schema`` by path (``observation/rgb``, ``step/reward``...)."""
    out = {f"{group}/{name}": f for group in GROUPS for name, f in getattr(schema, group).items()}
    out.update({f"step/{name}": f for name, f in STEP_FIELDS.items()})
    out.update({f"trajectory/{name}": f for name, f in TRAJECTORY_FIELDS.items()})
    return out


def _is_dataset(path: str) -> bool:
    try:
        return SCHEMA_ATTR in zarr.open_group(path, mode="r").attrs
    except Exception:  # not a zarr group, or unreadable
        return False


class TrajectoryDataset:
    """Trajectories on disk, in Agent-Arena's manner, in a zarr store that describes itself.

    Args:
      path: the store's directory.
      mode: ``"w"`` (create, replacing a dataset already there), ``"a"`` (append to, or create, and
        resume collection), ``"r"`` (read only).
      obs_config: the observations' field configs (``{name: {"shape", "dtype", "output_key", "compression"}}``
        or :class:`~jarena.data.schema.Field`) to create a store; in mode ``"a"`` on an existing store it is
        optional and must match the store's. Reading needs none.
      act_config: the actions' field configs, as ``obs_config``.
      goal_config: the goals' field configs, as ``obs_config`` (none for tasks without a goal).
      chunk_bytes: target bytes per zarr chunk of each array (when creating).

    Raises:
      DatasetError: an unknown mode, missing or mismatched configs, or a corrupt store; the store is
        left as it was.
    """

    def __init__(self, path: str | os.PathLike, mode: str = "r", *, obs_config: Mapping | None = None,
                 act_config: Mapping | None = None, goal_config: Mapping | None = None,
                 chunk_bytes: int = 4 << 20):
        if mode not in MODES:
            raise DatasetError(f"unknown mode {mode!r}; valid modes are {list(MODES)} (read, append, write)")
        self.path, self.mode = os.fspath(path), mode
        given = None
        if obs_config is not None or act_config is not None or goal_config:
            if obs_config is None or act_config is None:
                raise DatasetError("creating or checking a dataset needs both obs_config and act_config")
            given = Schema(observation=obs_config, action=act_config, goal=goal_config or {})
        self._pending: list[dict[str, Any]] = []
        self._lock = None
        self._set_committed(np.zeros((0,), np.int64), np.zeros((0,), np.int64))
        exists = os.path.exists(os.path.join(self.path, "zarr.json"))
        if mode == "r" and not exists:
            raise DatasetError(f"no dataset at {self.path!r}; create one with mode='w' (or 'a') and configs")
        if mode == "w" or (mode == "a" and not exists):
            if given is None:
                raise DatasetError(f"creating a dataset at {self.path!r} needs obs_config and act_config")
            self._create(given, chunk_bytes)
        self._open(given)

    # ------------------------------------------------------------------------------------------ opening
    def _create(self, schema: Schema, chunk_bytes: int) -> None:
        """Builds an empty store in a temporary directory, then moves it into place."""
        if os.path.exists(self.path) and os.listdir(self.path) and not _is_dataset(self.path):
            raise DatasetError(f"{self.path!r} exists and is not a jarena dataset; refusing to overwrite it")
        if os.path.exists(self.path):
            lock(self.path).close()  # raises if another process is writing to it
        parent = os.path.dirname(os.path.abspath(self.path))
        os.makedirs(parent, exist_ok=True)
        tmp = os.path.join(parent, f".{os.path.basename(os.path.abspath(self.path))}.{uuid.uuid4().hex}.tmp")
        root = zarr.open_group(tmp, mode="w")
        for name, field in _fields(schema).items():
            # Small items get fewer rows per chunk: growing a partly filled chunk rewrites it.
            rows = max(1, min(int(chunk_bytes) // max(field.itemsize, 1), MAX_CHUNK_ROWS))
            # Chunk files side by side ("c.7.0.0") rather than in a directory each ("c/7/0/0"): no mkdir per chunk.
            root.create_array(name, shape=(0,) + field.shape, chunks=(rows,) + field.shape, dtype=field.dtype,
                              compressors=_compressors(field), fill_value=0,
                              chunk_key_encoding={"name": "default", "separator": "."})
        commit = root.create_array(COMMIT, shape=(2,), chunks=(2,), dtype="int64", compressors=None, fill_value=0,
                                   chunk_key_encoding={"name": "default", "separator": "."})
        write_rows(commit, 0, [np.zeros(2, np.int64)])
        root.attrs.update({SCHEMA_ATTR: {"format": FORMAT, "schema": schema.to_json()}})
        old = None
        if os.path.exists(self.path):
            old = f"{tmp}.old"
            os.replace(self.path, old)
        os.replace(tmp, self.path)
        if old is not None:
            shutil.rmtree(old)

    def _read_root(self) -> tuple[zarr.Group, dict]:
        try:
            root = zarr.open_group(self.path, mode="r" if self.mode == "r" else "r+")
            return root, dict(root.attrs)
        except Exception as e:
            raise DatasetError(f"{self.path!r} is not a readable zarr store: {e}") from e

    def _open(self, given: Schema | None) -> None:
        root, meta = self._read_root()
        if SCHEMA_ATTR not in meta:
            raise DatasetError(f"{self.path!r} is not a jarena dataset (no {SCHEMA_ATTR!r} attribute)")
        info = meta[SCHEMA_ATTR]
        try:
            if info.get("format") != FORMAT:
                raise DatasetError(f"dataset format {info.get('format')!r}; this jarena reads format {FORMAT}")
            self.schema = Schema.from_json(info["schema"])
        except (KeyError, TypeError, AttributeError, DatasetError) as e:
            raise DatasetError(f"corrupt dataset at {self.path!r}: bad schema ({e})") from e
        if given is not None and self.mode == "a":
            diff = self.schema.differences(given)
            if diff:
                raise DatasetError(f"config mismatch on append to {self.path!r}:\n  " + "\n  ".join(diff))
        self._load(root, meta)
        if self.mode != "r":
            self._lock = lock(self.path)
            remove_partial_files(self.path)

    def _load(self, root: zarr.Group, meta: Mapping) -> None:
        """Opens the arrays and reads the commit record, checking that they agree."""
        arrays = {}
        for name, field in _fields(self.schema).items():
            try:
                array = root[name]
            except Exception as e:
                raise DatasetError(f"corrupt dataset at {self.path!r}: missing array {name!r} ({e})") from e
            if not isinstance(array, zarr.Array) or array.shape[1:] != field.shape or array.dtype != field.dtype:
                raise DatasetError(f"corrupt dataset at {self.path!r}: array {name!r} does not match its field "
                                   f"{field.to_json()}")
            # Chunks are written even when all zeros: it saves zarr a pass over every chunk it writes.
            arrays[name] = array if self.mode == "r" else array.with_config({"write_empty_chunks": True})
        try:
            commit = root[COMMIT]
            if not isinstance(commit, zarr.Array) or commit.shape != (2,) or commit.dtype != np.int64:
                raise ValueError(f"expected 2 int64 values, got {commit}")
            n, steps = (int(v) for v in commit[:])
        except Exception as e:
            raise DatasetError(f"corrupt dataset at {self.path!r}: bad commit record ({e})") from e
        if n < 0 or steps < 0:
            raise DatasetError(f"corrupt dataset at {self.path!r}: bad commit record ({n} trajectories, {steps} steps)")
        rows = {"observation": steps + n, "step": steps, "trajectory": n}
        for name, array in arrays.items():
            need = rows[ROWS_PER[name.split("/")[0]]]
            if array.shape[0] < need:
                raise DatasetError(f"corrupt dataset at {self.path!r}: array {name!r} has {array.shape[0]} rows, "
                                   f"the commit record needs {need}")
        lengths = read_rows(arrays["trajectory/length"], 0, n).astype(np.int64)
        if n and (lengths.min() < 1 or int(lengths.sum()) != steps):
            raise DatasetError(f"corrupt dataset at {self.path!r}: trajectory lengths sum to {int(lengths.sum())}, "
                               f"the commit record says {steps} steps")
        self._root, self._arrays, self._commit = root, arrays, commit
        self._set_committed(lengths, read_rows(arrays["trajectory/episode"], 0, n).astype(np.int64))

    def _set_committed(self, lengths: np.ndarray, episodes: np.ndarray) -> None:
        self._lengths, self._episodes = lengths, episodes
        self._step_offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)

    def refresh(self) -> None:
        """Re-reads the store: a reader then sees the trajectories a writer committed since it opened."""
        self._load(*self._read_root())

    def close(self) -> None:
        """Releases the writer's lock; an unfinished :meth:`add_transition` trajectory is dropped."""
        self._pending = []
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def __enter__(self) -> TrajectoryDataset:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"TrajectoryDataset({self.path!r}, mode={self.mode!r}, trajectories={self.num_trajectories()}, "
                f"steps={self.num_steps()})")

    # ------------------------------------------------------------------------------------------ reading
    def num_trajectories(self) -> int:
        return int(self._lengths.shape[0])

    def num_steps(self) -> int:
        """Transitions (actions) over all trajectories."""
        return int(self._step_offsets[-1])

    def lengths(self) -> np.ndarray:
        """int64 (num_trajectories,), the number of actions of each trajectory."""
        return self._lengths.copy()

    def episodes(self) -> np.ndarray:
        """int64 (num_trajectories,), the arena episode id of each trajectory (-1 when unknown)."""
        return self._episodes.copy()

    def array(self, name: str) -> zarr.Array:
        """The zarr array ``name`` (e.g. ``"observation/rgb"``); rows past the commit are not data."""
        return self._arrays[name]

    def rows(self, name: str, start: int, stop: int) -> np.ndarray:
        """Rows ``start : stop`` of array ``name`` (committed rows are data; later ones are not)."""
        return read_rows(self._arrays[name], start, stop)

    def get_trajectory(self, i: int) -> dict[str, Any]:
        """Trajectory ``i``: ``observation`` (T + 1, ...) and ``action`` (T, ...) dicts by output key, ``goal``
        dict, ``reward`` / ``terminated`` / ``truncated`` (T,), ``episode`` and ``length``."""
        n = self.num_trajectories()
        if not -n <= i < n:
            raise IndexError(f"trajectory {i} out of range for a dataset of {n} trajectories")
        i %= n
        s0, s1 = int(self._step_offsets[i]), int(self._step_offsets[i + 1])
        out: dict[str, Any] = {group: {} for group in GROUPS}
        for group in GROUPS:
            for name, f in getattr(self.schema, group).items():
                a, b = {"observation": (s0 + i, s1 + i + 1), "action": (s0, s1), "goal": (i, i + 1)}[group]
                rows = self.rows(f"{group}/{name}", a, b)
                out[group][f.output_key] = rows[0] if group == "goal" else rows
        for name in STEP_FIELDS:
            out[name] = self.rows(f"step/{name}", s0, s1)
        out.update(episode=int(self._episodes[i]), length=s1 - s0)
        return out

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return (self.get_trajectory(i) for i in range(self.num_trajectories()))

    def split(self, ratios: Sequence[float] | Mapping[str, float] = (0.8, 0.1, 0.1), seed: int = 0
              ) -> dict[str, np.ndarray]:
        """Trajectory indices per split (see :func:`jarena.data.splits.split_trajectories`)."""
        from jarena.data.splits import split_trajectories

        return split_trajectories(self.num_trajectories(), ratios, seed)

    def loader(self, batch_size: int, **kwargs):
        """A :class:`jarena.data.loader.Loader` over this dataset (same arguments after ``batch_size``)."""

        return Loader(self, batch_size, **kwargs)

    def sample(self, key, batch_size: int, mode: str = "transition", length: int | None = None,
               trajectories: Sequence[int] | None = None) -> dict[str, Any]:
        """One batch drawn with ``key``, read from disk (see :class:`jarena.data.loader.Loader`)."""
        return self.loader(batch_size, mode=mode, length=length, trajectories=trajectories,
                           memory_budget=0).sample(key)

    # ------------------------------------------------------------------------------------------ writing
    def add_trajectory(self, observations: Mapping[str, Any], actions: Mapping[str, Any] | Any, goal: Any = None, *,
                       rewards: Any = None, terminated: Any = None, truncated: Any = None, episode: int = -1) -> int:
        """Appends one trajectory of T steps; returns its index. Visible only once all of it is written.

        Args:
          observations: ``{field name: (T + 1, *shape)}``, the observations before each action and the last one
            reached; keys not in the schema are ignored.
          actions: ``{field name: (T, *shape)}``, or one array when the schema has one action field.
          goal: ``{field name: shape}``, or one array when the schema has one goal field.
          rewards: (T,) float (zeros by default); terminated, truncated: (T,) bool (false by default).
          episode: the arena's episode id, or -1.
        """
        return self.add_trajectories([dict(observations=observations, actions=actions, goal=goal, rewards=rewards,
                                           terminated=terminated, truncated=truncated, episode=episode)])[0]

    def add_trajectories(self, trajectories: Sequence[Mapping[str, Any]]) -> list[int]:
        """Appends several trajectories (each a dict of :meth:`add_trajectory`'s arguments) in one commit."""
        self._writable()
        if not trajectories:
            return []
        checked = [self._check(t, f"trajectory {k} of {len(trajectories)}" if len(trajectories) > 1 else "trajectory")
                   for k, t in enumerate(trajectories)]
        n, steps = self.num_trajectories(), self.num_steps()
        new_steps = sum(int(c["step/reward"].shape[0]) for c in checked)
        start = {"observation": steps + n, "step": steps, "trajectory": n}
        for name, array in self._arrays.items():
            pieces = [c[name] for c in checked]
            a = start[ROWS_PER[name.split("/")[0]]]
            b = a + sum(p.shape[0] for p in pieces)
            if array.shape[0] < b:  # grow the array's (metadata) shape fourfold: chunks past the data cost nothing
                array.resize((max(b, 4 * array.shape[0], 16 * array.chunks[0]),) + array.shape[1:])
            write_rows(array, a, pieces)
        # The commit point: one small file, replaced atomically.
        write_rows(self._commit, 0, [np.asarray([n + len(checked), steps + new_steps], np.int64)])
        self._set_committed(np.concatenate([self._lengths] + [c["trajectory/length"] for c in checked]),
                            np.concatenate([self._episodes] + [c["trajectory/episode"] for c in checked]))
        return list(range(n, n + len(checked)))

    def add_transition(self, observation: Mapping[str, Any], action: Mapping[str, Any] | Any,
                       next_observation: Mapping[str, Any], *, reward: float = 0.0, terminated: bool = False,
                       truncated: bool = False, goal: Any = None, episode: int = -1) -> int | None:
        """Adds one step to the trajectory being built; it is stored when ``terminated`` or ``truncated``
        (returning its index) or at :meth:`end_trajectory`. Until then it lives in memory only."""
        self._writable()
        self._pending.append(dict(observation=observation, action=action, next_observation=next_observation,
                                  reward=reward, terminated=terminated, truncated=truncated, goal=goal,
                                  episode=episode))
        return self.end_trajectory() if terminated or truncated else None

    def end_trajectory(self) -> int | None:
        """Stores the trajectory built by :meth:`add_transition` (if any); returns its index."""
        steps, self._pending = self._pending, []
        if not steps:
            return None

        def stack(key, of):
            return _stack([of(s) for s in steps], key)

        observations = {k: np.concatenate([np.asarray(steps[0]["observation"][k])[None],
                                           stack(k, lambda s: s["next_observation"][k])])
                        for k in self.schema.observation if k in steps[0]["observation"]}
        action = steps[0]["action"]
        actions = ({k: stack(k, lambda s: s["action"][k]) for k in action} if isinstance(action, Mapping)
                   else stack("action", lambda s: s["action"]))
        return self.add_trajectory(observations, actions, steps[0]["goal"],
                                   rewards=np.asarray([s["reward"] for s in steps], np.float32),
                                   terminated=np.asarray([s["terminated"] for s in steps], bool),
                                   truncated=np.asarray([s["truncated"] for s in steps], bool),
                                   episode=steps[0]["episode"])

    def _writable(self) -> None:
        if self.mode == "r":
            raise DatasetError(f"dataset {self.path!r} is open read-only; open it with mode='a' to append")
        if self._lock is None:
            raise DatasetError(f"dataset {self.path!r} is closed")

    def _check(self, trajectory: Mapping[str, Any], where: str) -> dict[str, np.ndarray]:
        """Validates one trajectory against the schema; returns its rows by array path (nothing written)."""
        actions = as_fields(trajectory["actions"], self.schema.action, "actions", where)
        steps = {v.shape[0] if v.ndim else None for v in actions.values()}
        if len(steps) != 1 or None in steps or min(steps) < 1:
            raise DatasetError(f"{where}: actions must share one leading length T >= 1, got leading axes "
                               f"{ {k: v.shape[:1] for k, v in actions.items()} }")
        (t,) = steps
        out = {}
        for group, data, lead in (("observation", trajectory["observations"], (t + 1,)), ("action", actions, (t,)),
                                  ("goal", trajectory.get("goal"), ())):
            fields = getattr(self.schema, group)
            if group == "goal" and not fields:
                if data is not None:
                    raise DatasetError(f"{where}: a goal was given but the dataset's schema has no goal fields")
                continue
            values = data if group == "action" else as_fields(data, fields, _ARGUMENT[group], where)
            for name, f in fields.items():
                out[f"{group}/{name}"] = conform(values[name], f, lead, f"{where}: {group} field {name!r}")[
                    None if group == "goal" else slice(None)]
        for name, f in STEP_FIELDS.items():
            value = trajectory.get({"reward": "rewards"}.get(name, name))
            value = np.zeros((t,), f.dtype) if value is None else value
            out[f"step/{name}"] = conform(value, f, (t,), f"{where}: {name}")
        out["trajectory/length"] = np.asarray([t], np.int64)
        out["trajectory/episode"] = np.asarray([int(trajectory.get("episode", -1))], np.int64)
        return out


# ---------------------------------------------------------------------------------------------- helpers
def _stack(values: list, what: str) -> np.ndarray:
    try:
        return np.stack([np.asarray(v) for v in values])
    except ValueError as e:
        raise DatasetError(f"add_transition: {what} changes shape within the trajectory ({e})") from e
