"""SAC (Haarnoja et al., 2018): twin critics, tanh-squashed Gaussian actor, automatic entropy temperature."""

from jarena_agents.sac.agent import SACConfig, SACState, SACTrainState, make_sac

__all__ = ["SACConfig", "SACState", "SACTrainState", "make_sac"]
