"""Whether unsynchronised clocks explain a straight line's misfit.

A profile stamped δ off the flange pose it is paired with lands where the sensor was δ
earlier or later: its corner moves by δ times the velocity of the point the sensor carries
there. A real arm's regional error moves the corners too, but by where the arm is, not by
how fast it moves. So where the corners lie farther from their line than the stated errors
explain (:meth:`~.target.LineTarget.check_fit`), their distances from it (the two
components across the line, each corner's) are regressed on that velocity's components
across the line, one δ for the recording, both centred (a shift of the whole recording is
the line's own); the F-test of that one-parameter regression
(:func:`scipy.special.fdtrc`) says whether a clock offset explains the misfit.

On the line target's test sweep (``line_features``, 248 corners) paired without its 12 ms
latency, the regression finds about 6 ms and 58 % of the distances (p far below 1e-12);
paired with the latency, 1 % (p about 0.01); on issue 29's recording 1 twin (an arm erring
by 0.2 mm by region, 28-29 corners paired right), 3-6 % (p 0.06-0.18).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import fdtrc

from ...geometry import FloatArray
from ...types import SampleFit
from .section import LineSection

#: False-alarm probability of the F-test below which clocks are said to explain a misfit.
CLOCK_FALSE_ALARM = 1e-4


class ClockEvidence(NamedTuple):
    """A clock offset's share of a line's misfit.

    Attributes
    ----------
    offset_s : float
        The offset that explains most (profile stamps minus pose stamps, s; its sign as the
        pairing's ``clock_offset_s`` would correct it).
    share : float
        Share of the corners' squared distances from the line (centred) it explains.
    p_value : float
        Probability of so large a share without a clock offset.
    """

    offset_s: float
    share: float
    p_value: float

    @property
    def explains(self) -> bool:
        """Whether the offset explains the misfit beyond chance (:data:`CLOCK_FALSE_ALARM`)."""
        return self.p_value < CLOCK_FALSE_ALARM

    def text(self) -> str:
        """The evidence in words, with units."""
        return (
            f"a clock offset of about {self.offset_s * 1e3:+.1f} ms between the profile and "
            f"pose stamps explains {self.share:.0%} of the corners' distances from the line "
            f"(F-test p = {self.p_value:.1g})"
        )


def clock_evidence(
    fits: list[SampleFit], section: LineSection, T_flange_sensor: FloatArray
) -> ClockEvidence | None:
    """The regression of the corners' distances from the line on their velocity (see the
    module docstring); None for fewer than 4 corners or a sensor that did not move."""
    if len(fits) < 4:
        return None
    fits = sorted(fits, key=lambda f: f.stamp_ns)
    c = section.sensor_corners(np.array([f.feature_xz for f in fits]))
    s = np.column_stack([c[:, 0], np.zeros(len(c)), c[:, 1]])
    T = np.stack([f.T_base_flange for f in fits]) @ T_flange_sensor
    t = np.array([f.stamp_ns for f in fits], dtype=np.float64) * 1e-9
    d = section.line.direction / np.linalg.norm(section.line.direction)

    def across(v: FloatArray) -> FloatArray:
        return np.asarray(v - np.outer(v @ d, d))

    carried = np.einsum("kij,kj->ki", T[:, :3, :3], s) + T[:, :3, 3]
    # The chord over each corner's two neighbours (one-sided at the ends), not
    # np.gradient's second-order weights: with uneven stamps those weigh the nearer
    # neighbour's pose error up, and the unsynchronised test sweep was no longer refused.
    before = np.r_[0, np.arange(len(t) - 1)]
    after = np.r_[np.arange(1, len(t)), len(t) - 1]
    moved = (
        np.einsum("kij,kj->ki", T[after, :3, :3], s)
        + T[after, :3, 3]
        - np.einsum("kij,kj->ki", T[before, :3, :3], s)
        - T[before, :3, 3]
    )
    dt = t[after] - t[before]
    if np.any(dt <= 0.0):
        return None
    e = across(carried - section.line.point)
    u = across(moved / dt[:, None])
    e -= e.mean(axis=0)
    u -= u.mean(axis=0)
    uu = float(np.sum(u * u))
    ee = float(np.sum(e * e))
    if uu <= 0.0 or ee <= 0.0:
        return None
    offset = float(np.sum(e * u)) / uu
    explained = offset * offset * uu
    dof = 2 * len(fits) - 3  # two components a corner; their means and the offset fitted
    share = explained / ee
    rest = max(ee - explained, 1e-300)
    return ClockEvidence(-offset, share, float(fdtrc(1, dof, explained / (rest / dof))))
