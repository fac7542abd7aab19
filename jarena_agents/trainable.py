"""Trainable agents: the agent protocol plus on-device training, train/eval policies and checkpoints."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import jax

from jarena.checkpoint import Checkpointer
from jarena.core.agent import Agent
from jarena.core.arena import Arena


@dataclasses.dataclass(frozen=True)
class TrainableAgent(Agent):
    """An :class:`~jarena.core.agent.Agent` that trains end to end on device.

    Attributes:
      init_training: ``(key, arena) -> train_state``: networks, optimiser, normaliser, RNG, counters,
        the arenas' batch state and any replay buffer (everything a run needs to continue bit for bit).
      train: ``(train_state, arena, num_updates) -> (train_state, metrics)``; a jittable chunk of
        updates (``arena`` and ``num_updates`` static). ``metrics`` leaves have a leading update axis
        and include ``episode_return`` and ``episodes`` (returns and counts of finished episodes).
      policy: ``(train_state, arena_spec, deterministic) -> agent_state`` for ``act``: the eval mode
        (``deterministic=True``) or the train mode (sampling) policy.
      settings: the typed config; has ``steps_per_update`` and ``total_steps``.
    """

    init_training: Any = None
    train: Any = None
    policy: Any = None
    settings: Any = dataclasses.field(default=None, compare=False, hash=False)

    @classmethod
    def wrap(cls, agent: Agent, **training) -> TrainableAgent:
        """Adds the training functions in ``training`` to a plain ``agent``."""
        return cls(**{f.name: getattr(agent, f.name) for f in dataclasses.fields(Agent)}, **training)

    def save(self, path: str | Path, train_state: Any, step: int, metadata: dict | None = None) -> None:
        """Writes ``train_state`` as checkpoint ``step`` under ``path`` (orbax; keeps the newest 3)."""
        checkpointer = Checkpointer(path)
        try:
            checkpointer.save(step, train_state, metadata)
        finally:
            checkpointer.close()

    def load(self, path: str | Path, arena: Arena, step: int | None = None) -> Any:
        """Reads checkpoint ``step`` (default: the latest) under ``path`` into a train state for ``arena``."""
        checkpointer = Checkpointer(path)
        try:
            if checkpointer.latest_step() is None:
                raise FileNotFoundError(f"no checkpoint under {path}")
            template = jax.jit(self.init_training, static_argnums=1)(jax.random.key(0), arena)
            state, _ = checkpointer.restore(template, step)
            return state
        finally:
            checkpointer.close()
