"""Scripted oracle agents that read privileged simulator state."""

from jarena_agents.oracles import cartpole, pendulum, point_mass  # noqa: F401  (registers the oracles)
