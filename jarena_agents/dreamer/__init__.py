"""``dreamer``: DreamerV3's actor-critic trained in a learned world model's imagination (:mod:`.agent`), with its
objectives in :mod:`.losses`."""

from jarena_agents.dreamer.agent import DreamerConfig, make_dreamer

__all__ = ["DreamerConfig", "make_dreamer"]
