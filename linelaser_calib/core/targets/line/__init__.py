"""The straight-line target: a seam or edge seen from many poses, no point taught.

Modules: :mod:`.model` (the line, the corner-to-line residual, the closed form), :mod:`.config`,
:mod:`.section` (the result section),
:mod:`.features` (each profile's corner), :mod:`.refine` (maximum likelihood),
:mod:`.observability` (what the views determine, in words) and :mod:`.target` (the plug-in).
"""

from __future__ import annotations

from .model import Line
from .section import LineSection
from .target import TARGET, LineTarget

__all__ = ["TARGET", "Line", "LineSection", "LineTarget"]
