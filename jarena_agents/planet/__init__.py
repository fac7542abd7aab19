"""``planet``: CEM planning over a world model learned online (:mod:`jarena_agents.planet.agent`)."""

from jarena_agents.planet.agent import PlaNetConfig, make_planet

__all__ = ["PlaNetConfig", "make_planet"]
