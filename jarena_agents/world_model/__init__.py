"""World models (DreamerV3's RSSM): :mod:`.model` for the model and its loss, :mod:`.networks` for its modules,
:mod:`.distributions` for symlog, two-hot and categorical latents."""

from jarena_agents.world_model import model
from jarena_agents.world_model.model import WorldModel, WorldModelConfig, make_world_model
from jarena_agents.world_model.networks import Latent

__all__ = ["Latent", "WorldModel", "WorldModelConfig", "make_world_model", "model"]
