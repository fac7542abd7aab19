"""Building arenas from strings."""

from jarena.building import transforms  # noqa: F401  (registers the built-in tools and tasks)
from jarena.building.builder import (
    TASKS,
    TOOLS,
    ArenaStringError,
    build_arena,
    list_arenas,
    register_arena_builder,
    register_task,
    register_tool,
)
from jarena.building.grammar import ArenaString, Call, parse_arena_string

__all__ = ["TASKS", "TOOLS", "ArenaString", "ArenaStringError", "Call", "build_arena", "list_arenas",
           "parse_arena_string", "register_arena_builder", "register_task", "register_tool"]
