"""Scripted oracle agents that read privileged simulator state."""

from jarena_agents.oracles import (  # noqa: F401  (registers the oracles)
    cartpole,
    cloth_flattening,
    cloth_folding,
    dmc_cartpole,
    dmc_point_mass,
    dmc_reacher,
    pendulum,
    point_mass,
    pusht,
    raven,
)
