"""A domain: one dynamics and sensor shared by several named tasks (as a dm_control domain)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

from jarena.core.dynamics import Dynamics, Sensor
from jarena.core.task import Task
from jarena.core.tool import ActionTool


@dataclasses.dataclass(frozen=True)
class Domain:
    """How to build the pieces of a domain's arenas.

    Attributes:
      name: domain name (``cartpole``).
      dynamics: ``() -> Dynamics``.
      sensor: ``() -> Sensor``.
      tasks: task name -> ``(**kwargs) -> Task`` building the task *without* its time limit.
      time_limit: default episode length in dynamics steps for every task of the domain.
      tool: ``() -> ActionTool`` applied by default (e.g. none for discrete control).
      tags: task name -> tags (e.g. ``("benchmark",)``).
      sensors: task name -> ``() -> Sensor`` for tasks that observe more than the domain's sensor
        (dm_control's observations are defined per task, e.g. finger turn adds its target).
      auto_reset: the arenas' default ``Arena.auto_reset`` (``lazy`` for expensive resets and episodes that
        end together).
      task_dynamics: task name -> ``() -> Dynamics`` for tasks whose physics differ from the domain's
        (dm_control's finger spin lowers the spinner's damping; reacher hard shrinks its target).
      unread_sensors: MJCF sensor types of the model that no task or observation of the domain reads
        (e.g. humanoid's ``touch``), which a builder may leave out of the simulation.
    """

    name: str
    dynamics: Callable[[], Dynamics]
    sensor: Callable[[], Sensor]
    tasks: Mapping[str, Callable[..., Task]]
    time_limit: int | None = None
    tool: Callable[[], ActionTool] | None = None
    tags: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)
    sensors: Mapping[str, Callable[[], Sensor]] = dataclasses.field(default_factory=dict)
    auto_reset: str = "select"
    task_dynamics: Mapping[str, Callable[[], Dynamics]] = dataclasses.field(default_factory=dict)
    unread_sensors: tuple[str, ...] = ()

    def sensor_for(self, task: str) -> Sensor:
        return self.sensors.get(task, self.sensor)()

    def dynamics_for(self, task: str) -> Dynamics:
        return self.task_dynamics.get(task, self.dynamics)()

    @property
    def default_task(self) -> str:
        return next(iter(self.tasks))
