"""The sphere target: a tooling ball scanned from many flange poses (see :mod:`.target`).

Modules: :mod:`.circle` (per-profile RANSAC circle), :mod:`.shape` (rival shapes and the
recording's own scale), :mod:`.model` (sphere centres from circles, side, fixed-point linear
solve and polish), :mod:`.refine` (point-to-sphere maximum likelihood on the shared solver),
:mod:`.config`, :mod:`.target` (the protocol implementation, the result section).
"""

from __future__ import annotations

from linelaser_calib.core.targets.sphere.config import SphereConfig
from linelaser_calib.core.targets.sphere.features import SphereFeature
from linelaser_calib.core.targets.sphere.section import SphereSection
from linelaser_calib.core.targets.sphere.target import SphereTarget

#: The registered sphere target.
TARGET = SphereTarget()

__all__ = ["TARGET", "SphereConfig", "SphereFeature", "SphereSection", "SphereTarget"]
