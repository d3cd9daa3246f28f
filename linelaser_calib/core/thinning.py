"""Near-duplicate samples: a bounded, representative subset where the information saturates.

A real arm errs by region (:mod:`.regions`): poses within :data:`~.regions.CLUSTER_RADIUS_M`
and :data:`~.regions.CLUSTER_ANGLE_RAD` of each other share most of their error. A 200 Hz
profiler on a moving arm records 12,000 profiles a minute, hundreds of them from each such
neighbourhood of flange poses; they add points, but not independent views of the hand-eye:
what they would tell beyond a few of them is the neighbourhood's one shared pose error, and
every profile costs the same to fit.

The rule (:func:`thin_samples`)
-------------------------------
The flange poses are binned on a grid of neighbourhoods centred on their mean pose: cells of
:data:`~.regions.CLUSTER_RADIUS_M` per axis of the base frame in position and of
:data:`~.regions.CLUSTER_ANGLE_RAD` per component of the rotation vector from the samples'
mean orientation (a rotation vector near the mean bends the angles little). A cell holding
more than ``per_neighbourhood`` samples keeps that many, evenly spaced in time (its first and
last among them), so that each pass of the arm through the cell stays represented; the others
are set aside before any feature is extracted (the clock-offset search thins the samples it
pairs alike, and the calibration keeps the ones it kept). A recording whose every cell holds
``per_neighbourhood`` samples or fewer is left whole; ``per_neighbourhood`` 0 turns the rule
off.

The work is then bounded by the pose-space coverage (cells × ``per_neighbourhood``), not by
the profile count. The 1σ stays honest: the solve sees fewer samples per neighbourhood, each
with its own pose error, and its 1σ grows as it should where they were not independent; the
self-check (:mod:`.selfcheck`) judges the robot's error by region on the samples kept.

All lengths in m and angles in rad; text in mm and degrees.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from .geometry import FloatArray
from .regions import CLUSTER_ANGLE_RAD, CLUSTER_RADIUS_M
from .types import Sample

#: Default most samples kept per neighbourhood of flange poses (:func:`thin_samples`): more
#: than any stop-and-go recording holds there (the committed bags: at most 18, a sweep of the
#: line target), and on a 100 Hz sweep of 3,145 profiles it keeps 1,522 and moves the
#: hand-eye by 0.12 of its 1σ from the full run's (docs/benchmarks.md, "Near-duplicate
#: profiles").
DEFAULT_PER_NEIGHBOURHOOD = 20


@dataclass(frozen=True)
class Thinning:
    """What :func:`thin_samples` did (the result's ``quality.thinning``).

    Attributes
    ----------
    kept, total : int
        Samples kept, of the samples given.
    neighbourhoods : int
        Cells of the grid that hold a sample.
    thinned : int
        Cells that held more than ``per_neighbourhood`` samples.
    per_neighbourhood : int
        Most samples kept per cell.
    cell_m, cell_rad : float
        The cell's side in position, m, and in rotation vector, rad.
    """

    kept: int
    total: int
    neighbourhoods: int
    thinned: int
    per_neighbourhood: int
    cell_m: float = CLUSTER_RADIUS_M
    cell_rad: float = CLUSTER_ANGLE_RAD

    @property
    def set_aside(self) -> int:
        """Samples set aside."""
        return self.total - self.kept

    def sentence(self) -> str:
        """What was done, in one sentence (mm and degrees); '' where nothing was set aside."""
        if not self.set_aside:
            return ""
        return (
            f"{self.set_aside} of {self.total} profiles were set aside as near-duplicates: "
            f"{self.thinned} of the {self.neighbourhoods} neighbourhoods of flange poses "
            f"({self.cell_m * 1e3:.0f} mm x {np.degrees(self.cell_rad):.0f} deg cells) held "
            f"more than {self.per_neighbourhood} and kept that many, evenly spaced in time"
        )


def neighbourhood_labels(T_base_flange: FloatArray) -> NDArray[np.int64]:
    """Cell label (M,) of each flange pose (M, 4, 4): equal labels, one neighbourhood. The
    grid is centred on the mean pose (a cell's centre there, not a corner)."""
    rotations = Rotation.from_matrix(T_base_flange[:, :3, :3])
    turned = (rotations.mean().inv() * rotations).as_rotvec()
    shifted = T_base_flange[:, :3, 3] - T_base_flange[:, :3, 3].mean(axis=0)
    keys = np.concatenate(
        [
            np.floor(shifted / CLUSTER_RADIUS_M + 0.5),
            np.floor(turned / CLUSTER_ANGLE_RAD + 0.5),
        ],
        axis=1,
    ).astype(np.int64)
    return np.asarray(np.unique(keys, axis=0, return_inverse=True)[1], dtype=np.int64).reshape(-1)


def thin_samples(
    samples: list[Sample], per_neighbourhood: int, chosen: Collection[int] | None = None
) -> tuple[list[Sample], Thinning | None]:
    """At most ``per_neighbourhood`` samples per neighbourhood of flange poses, evenly spaced
    in time (see the module docstring), in the samples' order, and what was done (None where
    ``per_neighbourhood`` is 0: every sample kept, nothing looked at).

    ``chosen``, when given, are the indices of the samples an earlier thinning of the same
    profiles kept (a clock-offset search, at flange poses a few ms away): those are kept, so
    that the features extracted then serve again. The neighbourhoods are counted anew."""
    if per_neighbourhood < 0:
        raise ValueError(f"per_neighbourhood must be >= 0, got {per_neighbourhood}")
    if per_neighbourhood == 0 or not samples:
        return samples, None
    labels = neighbourhood_labels(np.stack([s.T_base_flange for s in samples]))
    counts = np.bincount(labels)
    full = np.flatnonzero(counts > per_neighbourhood)
    if chosen is not None:
        keep = np.isin([s.index for s in samples], np.fromiter(chosen, dtype=np.int64))
    else:
        stamps = np.array([s.stamp_ns for s in samples])
        keep = np.ones(len(samples), dtype=bool)
        for cell in full:
            members = np.flatnonzero(labels == cell)
            members = members[np.argsort(stamps[members], kind="stable")]
            picked = np.round(np.linspace(0, len(members) - 1, per_neighbourhood))
            keep[members] = False
            keep[members[picked.astype(np.int64)]] = True
    kept = samples if keep.all() else [s for s, k in zip(samples, keep, strict=True) if k]
    return kept, Thinning(
        kept=len(kept),
        total=len(samples),
        neighbourhoods=len(counts),
        thinned=len(full),
        per_neighbourhood=per_neighbourhood,
    )
