"""``planet``: CEM planning over a world model learned online or from a dataset (:mod:`jarena_agents.planet.agent`,
:mod:`jarena_agents.planet.offline`)."""

from jarena_agents.planet.agent import PlaNetConfig, make_planet

__all__ = ["PlaNetConfig", "make_planet"]
