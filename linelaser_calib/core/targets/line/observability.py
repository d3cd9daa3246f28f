"""What the views of a straight seam determine of the hand-eye, in plain words.

A line is unchanged by sliding along itself and by turning about itself. Seen from one
view, a hand-eye change that moves the corner along the seam, or that turns the laser plane
about the seam, looks like no change at all. So:

- a translation of the sensor along the seam (as seen from the flange) is determined only
  when the flange turns between views so that the seam's direction in the flange frame
  changes: turning the laser plane about the viewing axis, or tipping it along the seam;
- a rotation of the sensor about an axis parallel to the seam (as seen from the sensor) is
  determined only when the seam is seen at different places of the laser plane (a sideways
  weave along the laser line and a change of depth) and from tilted views;
- with one flange orientation throughout, the three translations are not determined at all:
  every corner moves by the same base-frame vector, which the line's position absorbs.

The data-only information of the hand-eye (line and pose corrections marginalised, the
initial hand-eye's prior left out) is eigen-analysed in lever-scaled units by the shared
machinery (:func:`~linelaser_calib.core.observability.scaled_eigen`,
:func:`~linelaser_calib.core.observability.poor_directions`); each weak or unobservable
direction is named by its relation to the seam.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...geometry import project_to_so3, rotvec_from_matrix
from ...observability import ROTATION_SHARE, Direction, poor_directions, scaled_eigen
from ...types import FloatArray
from .model import Line

#: A direction within this angle of the seam counts as along (or about) it, rad.
SEAM_ALIGNED_RAD = math.radians(20.0)


def _fmt(v: FloatArray) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def _angle(a: FloatArray, b: FloatArray) -> float:
    """Sign-free angle between two unit vectors, rad."""
    return math.acos(min(1.0, abs(float(a @ b))))


@dataclass(frozen=True)
class LineObservability:
    """The outcome of :func:`analyse_line`.

    Attributes
    ----------
    sigma_m : ndarray, shape (6,)
        1σ from the views alone per eigen-direction, m (rotations times the lever), largest
        first.
    lever_m : float
        Median distance of the corners from the sensor origin, m.
    directions : list of Direction
        Unobservable ones first, then weak ones.
    orientation_spread_rad : float
        Largest angle between a flange orientation and their mean, rad.
    seam_turn_rad : float
        Largest angle between the seam's direction in the flange frame in one view and its
        mean over the views, rad.
    """

    sigma_m: FloatArray
    lever_m: float
    directions: list[Direction]
    orientation_spread_rad: float
    seam_turn_rad: float

    @property
    def unobservable(self) -> list[Direction]:
        """Directions the views cannot determine."""
        return [d for d in self.directions if d.status == "unobservable"]

    def statement(self) -> str:
        """What the views determine, in plain words (mm, deg)."""
        text = (
            f"The flange orientations span ±{math.degrees(self.orientation_spread_rad):.1f} deg "
            f"and the seam's direction seen from the flange turns by up to "
            f"{math.degrees(self.seam_turn_rad):.1f} deg"
        )
        missing = self.unobservable
        if not missing:
            return (
                text + f". The views determine the whole hand-eye (worst direction 1 sigma "
                f"{float(np.max(self.sigma_m)) * 1e3:.3f} mm at a {self.lever_m * 1e3:.0f} mm "
                "lever)."
            )
        items = " ".join(f"({k + 1}) {d.description}." for k, d in enumerate(missing))
        return (
            text + f". The views determine {6 - len(missing)} of the 6 hand-eye directions; not "
            f"determined: {items}"
        )

    def warnings(self) -> list[str]:
        """The statement when a direction is weak or undetermined; else nothing."""
        if not self.directions:
            return []
        weak = [d for d in self.directions if d.status == "weak"]
        text = self.statement()
        if weak:
            text += " Weakly determined: " + " ".join(
                f"({k + 1}) {d.description}." for k, d in enumerate(weak)
            )
        return [text]


def _describe(
    vector: FloatArray,
    status: str,
    sigma_m: float,
    lever_m: float,
    seam_in_sensor: FloatArray,
    seam_in_flange: FloatArray,
) -> str:
    """Plain words for one direction (scaled units, see :class:`Direction`)."""
    verdict = (
        "cannot be determined from these views"
        if status == "unobservable"
        else f"is only weakly determined (1 sigma {sigma_m * 1e3:.3f} mm)"
    )
    if float(vector[:3] @ vector[:3]) >= ROTATION_SHARE:
        axis = vector[:3] / np.linalg.norm(vector[:3])
        if _angle(axis, seam_in_sensor) < SEAM_ALIGNED_RAD:
            return (
                f"a rotation of the sensor about an axis parallel to the seam (direction "
                f"{_fmt(axis)}, sensor frame) {verdict}: turning about the seam moves no corner "
                "off it. To determine it, see the seam at different places of the laser line "
                "(weave sideways by 20 mm or more) and at different depths, from views tilted "
                "across the seam"
            )
        return (
            f"a rotation of the sensor about {_fmt(axis)} (sensor frame) {verdict}. To "
            "determine it, tilt the flange between views about different axes by 10-20 deg "
            "and weave the seam across the laser line"
        )
    direction = vector[3:] / np.linalg.norm(vector[3:])
    if _angle(direction, seam_in_flange) < SEAM_ALIGNED_RAD:
        return (
            f"a translation of the sensor along the seam (direction {_fmt(direction)}, flange "
            f"frame, lever {lever_m * 1e3:.0f} mm) {verdict}: sliding along the seam moves no "
            "corner off it. To determine it, turn the laser plane about the viewing axis and "
            "tip it along the seam between views, by 20 deg or more"
        )
    return (
        f"a translation of the sensor along {_fmt(direction)} (flange frame) {verdict}: the "
        "line's position absorbs it. To determine it, tilt the flange between views by 20 deg "
        "or more about axes across the seam"
    )


def analyse_line(
    information_data: FloatArray,
    corners_xz: FloatArray,
    T_base_flange: FloatArray,
    T_flange_sensor: FloatArray,
    line: Line,
    weak_sigma_m: float,
    unobservable_sigma_m: float,
) -> LineObservability:
    """Which hand-eye directions the views of a seam determine, in plain words.

    Parameters
    ----------
    information_data : ndarray, shape (6, 6)
        Data-only information of ``[θ (rad, sensor axes), ρ (m, flange axes)]``.
    corners_xz : ndarray, shape (M, 2)
        Corners in the sensor x-z plane, m.
    T_base_flange : ndarray, shape (M, 4, 4)
    T_flange_sensor : ndarray, shape (4, 4)
        The estimate the information was formed at.
    line : Line
        The seam, base frame.
    weak_sigma_m, unobservable_sigma_m : float
        Thresholds of the 1σ (m; rotations times the lever).
    """
    lever = float(np.median(np.hypot(corners_xz[:, 0], corners_xz[:, 1])))
    _, eigenvectors, sigma = scaled_eigen(information_data, lever)
    R = T_base_flange[:, :3, :3]
    R_mean = project_to_so3(np.sum(R, axis=0))
    spread = float(np.max(np.linalg.norm(rotvec_from_matrix(R @ R_mean.T), axis=-1)))
    seam_flange = np.einsum("mji,j->mi", R, line.direction)
    mean = np.sum(seam_flange, axis=0)
    mean /= np.linalg.norm(mean)
    turn = float(np.max(np.arccos(np.clip(seam_flange @ mean, -1.0, 1.0))))
    seam_sensor = T_flange_sensor[:3, :3].T @ mean
    directions = [
        Direction(
            d.vector,
            d.sigma_m,
            d.status,
            _describe(d.vector, d.status, d.sigma_m, lever, seam_sensor, mean),
        )
        for d in poor_directions(eigenvectors, sigma, weak_sigma_m, unobservable_sigma_m)
    ]
    return LineObservability(
        sigma_m=np.asarray(np.sort(sigma)[::-1], dtype=np.float64),
        lever_m=lever,
        directions=directions,
        orientation_spread_rad=spread,
        seam_turn_rad=turn,
    )
