"""Each profile's features extracted once per run: the run's features of every target.

One run may ask for the same target's features of the same profiles more than once: the
clock-offset search and then the fit at the offset found
(:mod:`linelaser_calib.core.offset_search`), and a rival target's own offset search and
then its fit at that offset (:mod:`.rivals`). The profiles are the same; only the flange
pose each is paired with differs. A run holds one :class:`Extractions` (never a global):
it extracts a target's features (with its settings and the run's seed) once, and where the
target's features do not depend on the flange poses (its ``with_samples``,
:func:`~.base.feature_repairing`) hands the same features re-paired with the samples asked
for, when those are of profiles it holds. A target whose features depend on the poses is
extracted again each time, as before.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

from ..types import Rejection, Sample
from .base import Progress, Target, _no_progress, feature_repairing


@dataclass(frozen=True)
class _Held:
    """One target's features (and rejections) of the profiles ``indices``."""

    indices: frozenset[int]
    features: list[Any]
    rejections: list[Rejection]


class Extractions:
    """The features of one run's profiles, each target's extracted once (see the module
    docstring).

    Parameters
    ----------
    seed : int
        The run's seed (each sample's random draws: :func:`~.runs.sample_rng`).
    workers : int
        As :meth:`~.base.Target.extract`'s (the same features, less wall time on a second
        core).
    """

    def __init__(self, seed: int, workers: int = 1) -> None:
        self.seed = seed
        self.workers = workers
        self._held: dict[tuple[str, Hashable], _Held] = {}

    def of(
        self,
        target: Target[Any],
        config: Any,
        samples: list[Sample],
        progress: Progress = _no_progress,
    ) -> tuple[list[Any], list[Rejection]]:
        """``target``'s features of ``samples`` with ``config`` and the rejections of the
        others, as :meth:`~.base.Target.extract` gives them: those held, re-paired with
        ``samples``, where the target allows it and every profile of ``samples`` was
        extracted before with the same config (the features and rejections of those
        profiles, in the held order); extracted (and held) otherwise. ``progress`` hears of
        an extraction only."""
        repairing = feature_repairing(target)
        key = (target.name, config) if repairing is not None else None
        held = None if key is None else self._held.get(key)
        wanted = {s.index for s in samples}
        if repairing is not None and held is not None and wanted <= held.indices:
            return (
                repairing([f for f in held.features if f.index in wanted], samples),
                [r for r in held.rejections if r.index in wanted],
            )
        features, rejections = target.extract(samples, config, self.seed, progress, self.workers)
        if key is not None:
            self._held[key] = _Held(frozenset(wanted), features, rejections)
        return features, rejections
