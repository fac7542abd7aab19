"""``chain(...)``: compose tasks, or action tools, into one transform of the same kind."""

from __future__ import annotations

from jarena.core.task import Task
from jarena.core.tool import ActionTool


def chain(*transforms: Task | ActionTool) -> Task | ActionTool:
    """Composes transforms of one kind, left to right (``chain(walk(), time_limit(1000))``).

    Args:
      *transforms: all :class:`Task` or all :class:`ActionTool`; nested chains are fine.

    Returns:
      A transform of the same kind whose state and params are tuples with one slot per member.
    """
    if not transforms:
        raise ValueError("chain() needs at least one Task or ActionTool")
    kinds = {type(t) for t in transforms}
    if len(kinds) != 1 or not issubclass(kinds.pop(), Task | ActionTool):
        names = sorted({type(t).__name__ for t in transforms})
        raise TypeError(f"chain() composes transforms of one kind (all Task or all ActionTool), got {names}")
    return type(transforms[0]).chain(*transforms)
