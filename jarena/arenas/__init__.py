"""Built-in arenas; importing this package registers their builders."""

from jarena.arenas import brax, classic, cloth, dmc, host, pusht, raven  # noqa: F401
