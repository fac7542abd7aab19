"""Checkpoints of training states through orbax, resumable bit for bit.

A training state is any pytree of arrays (network and optimiser state, normaliser, RNG keys, step
counters, the arenas' batch state, replay buffers). Typed PRNG keys are stored as their raw key data
and re-wrapped on restore, using the structure of a template state (e.g. a freshly initialised
one). JSON metadata (training history) is saved beside each step.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import orbax.checkpoint as ocp


def _is_key(x) -> bool:
    return hasattr(x, "dtype") and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)


def _to_storable(tree) -> dict[str, Any]:
    """The non-empty leaves, keyed by position (orbax cannot store zero-size arrays); keys as raw data."""
    leaves = jax.tree_util.tree_leaves(tree)
    return {f"leaf_{i:05d}": jax.random.key_data(x) if _is_key(x) else x
            for i, x in enumerate(leaves) if x.size > 0}


def _from_storable(stored: dict[str, Any], template):
    leaves, treedef = jax.tree_util.tree_flatten(template)
    out = []
    for i, t in enumerate(leaves):
        x = stored.get(f"leaf_{i:05d}", t)  # empty leaves come from the template
        out.append(jax.random.wrap_key_data(x, impl=jax.random.key_impl(t)) if _is_key(t) and x is not t else x)
    return jax.tree_util.tree_unflatten(treedef, out)


def _abstract(t) -> jax.ShapeDtypeStruct:
    """What a restored leaf looks like: the template's shape, dtype and, for a device array, its layout on the
    devices (a run on a mesh restores its sharded state as it was laid out)."""
    return jax.ShapeDtypeStruct(t.shape, t.dtype, sharding=t.sharding if isinstance(t, jax.Array) else None)


class Checkpointer:
    """Saves and restores training states under ``directory`` by integer step.

    Args:
      directory: where checkpoints live (created if needed).
      max_to_keep: how many recent checkpoints to keep.
    """

    def __init__(self, directory: str | Path, max_to_keep: int = 3):
        self.directory = Path(directory).absolute()
        options = ocp.CheckpointManagerOptions(max_to_keep=max_to_keep, create=True)
        self.manager = ocp.CheckpointManager(self.directory, options=options)

    def latest_step(self) -> int | None:
        return self.manager.latest_step()

    def save(self, step: int, state: Any, metadata: dict | None = None) -> None:
        """Saves ``state`` (and JSON ``metadata``) as ``step``; waits until it is on disk."""
        self.manager.save(step, args=ocp.args.Composite(state=ocp.args.StandardSave(_to_storable(state)),
                                                        metadata=ocp.args.JsonSave(metadata or {})))
        self.manager.wait_until_finished()

    def metadata(self, step: int | None = None) -> dict:
        """The JSON metadata saved with ``step`` (default: latest), without reading the state."""
        step = self.latest_step() if step is None else step
        if step is None:
            raise FileNotFoundError(f"no checkpoint in {self.directory}")
        restored = self.manager.restore(step, args=ocp.args.Composite(metadata=ocp.args.JsonRestore()))
        return dict(restored["metadata"] or {})

    def restore(self, template: Any, step: int | None = None) -> tuple[Any, dict]:
        """Restores the state at ``step`` (default: latest) with the structure of ``template``.

        ``template`` is a concrete state of the same structure (e.g. a freshly initialised one).
        """
        step = self.latest_step() if step is None else step
        if step is None:
            raise FileNotFoundError(f"no checkpoint in {self.directory}")
        abstract = jax.tree_util.tree_map(_abstract, _to_storable(template))
        restored = self.manager.restore(step, args=ocp.args.Composite(state=ocp.args.StandardRestore(abstract),
                                                                      metadata=ocp.args.JsonRestore()))
        return _from_storable(restored["state"], template), dict(restored["metadata"] or {})

    def close(self) -> None:
        self.manager.close()
