"""Action-tool transforms that compose with :func:`jarena.chain`."""

from jarena.tools.delay import delay
from jarena.tools.noise import noise
from jarena.tools.repeat import repeat
from jarena.tools.rescale import clip, rescale
from jarena.tools.sticky import sticky

__all__ = ["clip", "delay", "noise", "repeat", "rescale", "sticky"]
