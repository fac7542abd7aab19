"""Built-in arenas; importing this package registers their builders."""

from jarena.arenas import classic, dmc  # noqa: F401
