"""Sensor transforms: sensors built on other sensors (frame stacks)."""

from jarena.sensors.frame_stack import frame_stack

__all__ = ["frame_stack"]
