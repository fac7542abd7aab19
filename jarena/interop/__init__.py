"""Interop with other ecosystems: ``jarena.interop.gymnasium`` (needs ``pip install jarena[gymnasium]``).

Import the submodule you need; importing ``jarena`` imports none of them (nor their dependencies).
"""
