"""A griffe extension for the API reference: the library's docstrings mark names with reST roles
(``:func:`list_arenas```, ``:class:`~jarena.core.arena.Arena```), which Markdown would show as written; each role
becomes a code span of its name (the last part, where the role's name starts with ``~``)."""

from __future__ import annotations

import re

import griffe

ROLE = re.compile(r":(?:mod|func|class|data|meth|attr|obj|exc|const):`(~?)([^`]+)`")


def _code(match: re.Match) -> str:
    tilde, name = match.groups()
    return f"`{name.rsplit('.', 1)[-1] if tilde else name}`"


class ReSTRoles(griffe.Extension):
    def on_object(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = ROLE.sub(_code, obj.docstring.value)
