"""Interop with other ecosystems: ``jarena.interop.gymnasium`` (needs ``pip install jarena[gymnasium]``) and
``jarena.interop.dm_env`` (dm_env comes with dm-control, a dependency).

Import the submodule you need; importing ``jarena`` imports none of them (nor their dependencies).
"""
