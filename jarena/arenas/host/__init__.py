"""Host arenas: simulators that are not written in JAX (Gymnasium envs, simulators behind a socket, robots)
as arenas, stepped on the host from inside compiled programs.

An arena's state holds a handle on its simulator (:class:`~jarena.arenas.host.pieces.HostPhysics`), its
steps are host calls (``io_callback``, one per batch of arenas: :mod:`jarena.arenas.host.calls`) into a pool
of vector envs (:mod:`jarena.arenas.host.pool`), and finished episodes restart in place under the ``host``
auto-reset (:mod:`jarena.core.resets`). So ``evaluate``, ``collect``, ``run`` and ``train_and_evaluate`` run
every agent that acts on observations (random, PPO, SAC, BC, Dreamer, PlaNet's data collection) on them
unchanged; agents that read or roll forward the true state (planners, oracles) cannot, and say so.

What differs from a JAX arena, by nature: a state is a handle, not a value (stepping one state twice steps
the simulator twice); the arenas of one ``batch_reset`` step together (never a subset, never sharded over
devices); params are empty (a simulator's constants are its own); and steps cost host round trips.

- :func:`from_gymnasium` / ``gym|id:CartPole-v1``: any Gymnasium env (:mod:`jarena.arenas.host.gymnasium`).
- :func:`episode_seed`: the simulator seed of a jarena episode id.
"""

from jarena.arenas.host.gymnasium import from_gymnasium
from jarena.arenas.host.pieces import HostPhysics, episode_seed
from jarena.arenas.host.pool import EnvPool, HostArenaError

__all__ = ["EnvPool", "HostArenaError", "HostPhysics", "episode_seed", "from_gymnasium"]
