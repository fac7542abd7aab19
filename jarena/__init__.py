"""jarena: JAX-native arenas and agents.

Arenas are pure functions (``reset``, ``step``) over immutable pytrees; tasks and action tools are
composable transforms; everything builds from a string::

    import jarena
    arena = jarena.build_arena("classic|domain:cartpole,task:balance")
    state, info = arena.reset(jax.random.key(0))
"""

from jarena import _headless  # noqa: F401, I001  (first: picks MuJoCo's headless GL before mujoco is imported)
from jarena import arenas as _arenas  # noqa: F401  (registers the built-in builders)
from jarena import data, distributed, sensors, tasks, testing, tools
from jarena.building import (
    ArenaStringError,
    build_arena,
    list_arenas,
    parse_arena_string,
    register_arena_builder,
    register_task,
    register_tool,
)
from jarena.configs import retrieve_config
from jarena.core import spec
from jarena.core.agent import Agent
from jarena.core.arena import Arena, ArenaSpec
from jarena.core.batching import auto_reset, batch_reset, batch_step
from jarena.core.chain import chain
from jarena.core.dynamics import Dynamics, Sensor, SensorMemory
from jarena.core.spec import Box, Discrete, SpecError
from jarena.core.task import Task
from jarena.core.tool import ActionTool
from jarena.core.types import ArenaParams, ArenaState, Final, Info, Outcome, Transition
from jarena.data import TrajectoryDataset, collect, make_buffer
from jarena.runners import (EvalResult, Recording, Trajectory, evaluate, evaluate_policies, perform_parallel,
                            record_video, run, validate)
from jarena.training import SeedsResult, TrainResult, train_and_evaluate, train_seeds

__version__ = "0.1.0"

__all__ = [
    "ActionTool", "Agent", "Arena", "ArenaParams", "ArenaSpec", "ArenaState", "ArenaStringError", "Box",
    "Discrete", "Dynamics", "EvalResult", "Final", "Recording", "Info", "Outcome", "SeedsResult", "Sensor",
    "SensorMemory", "SpecError", "Task",
    "TrainResult", "Trajectory", "TrajectoryDataset", "Transition", "auto_reset", "batch_reset", "batch_step",
    "build_arena", "chain", "collect", "data", "distributed", "evaluate", "evaluate_policies", "list_arenas",
    "make_buffer",
    "parse_arena_string", "perform_parallel", "record_video", "register_arena_builder", "register_task",
    "register_tool", "retrieve_config",
    "run", "sensors", "spec", "tasks", "testing", "tools", "train_and_evaluate", "train_seeds",
    "validate",
]
