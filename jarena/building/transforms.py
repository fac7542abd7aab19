"""Registers the built-in action tools and task transforms under their names for arena strings."""

from jarena import tasks, tools
from jarena.building.builder import register_task, register_tool

for _name in ["rescale", "clip", "repeat", "noise", "delay", "sticky"]:
    register_tool(_name, getattr(tools, _name))
for _name in ["time_limit", "reward_scale", "success_bonus"]:
    register_task(_name, getattr(tasks, _name))
