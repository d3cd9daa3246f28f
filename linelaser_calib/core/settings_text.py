"""How core messages name a user setting: a neutral placeholder that each front end spells
its own way (a command-line flag, a node parameter; ``linelaser_calib.settings.render``).

A message writes ``{setting:radius_m}`` (in an f-string: ``setting("radius_m")``), never
``--radius``: the nodes' users have no flags.
"""

from __future__ import annotations

#: The placeholder's pattern; its one group is the setting's neutral name.
PLACEHOLDER = r"\{setting:(\w+)\}"


def setting(name: str) -> str:
    """The placeholder naming the user setting ``name`` in a message."""
    return "{setting:" + name + "}"
