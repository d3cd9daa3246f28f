"""The registry of calibration targets: one line per target (see :mod:`.base`).

A target's module is imported when it is first asked for, so a command pays only for the
target it uses.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from ..errors import InputError
from .base import Target

#: Target name (the ``--target`` value) -> module whose ``TARGET`` implements it.
REGISTRY: dict[str, str] = {
    "cylinder": "linelaser_calib.core.targets.cylinder",
    "known_point": "linelaser_calib.core.targets.known_point",
    "sphere": "linelaser_calib.core.targets.sphere",
    "line": "linelaser_calib.core.targets.line",
}

#: The target used when none is chosen.
DEFAULT_TARGET = "cylinder"


def target_names() -> tuple[str, ...]:
    """Every registered target's name, in registry order."""
    return tuple(REGISTRY)


def get_target(name: str) -> Target[Any]:
    """The target called ``name``.

    Raises
    ------
    InputError
        For an unknown name; the message lists the known ones.
    """
    if name not in REGISTRY:
        raise InputError(f"unknown target {name!r}; known targets: {', '.join(REGISTRY)}")
    target: Target[Any] = import_module(REGISTRY[name]).TARGET
    return target


def all_targets() -> list[Target[Any]]:
    """Every registered target (imports them all)."""
    return [get_target(name) for name in REGISTRY]


def plannable_target_names() -> tuple[str, ...]:
    """The targets whose poses can be planned (those with a ``planner``; imports them all)."""
    return tuple(t.name for t in all_targets() if getattr(t, "planner", None) is not None)
