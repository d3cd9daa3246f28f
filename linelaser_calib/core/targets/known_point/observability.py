"""Which hand-eye directions the views of one point determine, in plain words.

The data-only information of the hand-eye (nuisance and point marginalised, initial-guess
prior left out) is eigen-analysed in lever-scaled units, as the cylinder refinement does; see
:mod:`.target` for the patterns (one flange orientation, a point seen along one line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ...geometry import FloatArray, project_to_so3, rotvec_from_matrix
from ...observability import Direction, poor_directions, scaled_eigen
from .config import KnownPointConfig

#: Flange orientations spanning less than this count as one orientation, rad.
SAME_ORIENTATION_RAD = math.radians(2.0)
#: Corner points whose second principal spread is below this share of the first lie on a line.
COLLINEAR_RATIO = 0.05
#: A rotation direction within this angle of the corners' line is "about that line", rad.
LINE_ALIGNED_RAD = math.radians(15.0)
#: A direction with at least this share of its (scaled) length in rotation is a rotation.
ROTATION_SHARE = 0.5


@dataclass(frozen=True)
class KnownPointObservability:
    """What the views determine of the hand-eye (see the module docstring).

    Attributes
    ----------
    sigma_m : ndarray, shape (6,)
        1σ from the views alone per eigen-direction of the information, m (rotations times
        the lever), largest first.
    lever_m : float
        Median distance of the corners from the sensor origin, m.
    directions : list of Direction
        Unobservable ones first, then weak ones.
    orientation_spread_rad : float
        Largest angle between a flange orientation and their mean, rad.
    corner_spread_m : ndarray, shape (2,)
        Standard deviations of the corners along their two principal directions in the
        laser plane, m.
    point_estimated : bool
    """

    sigma_m: FloatArray
    lever_m: float
    directions: list[Direction]
    orientation_spread_rad: float
    corner_spread_m: FloatArray
    point_estimated: bool

    @property
    def unobservable(self) -> list[Direction]:
        """Directions the views cannot determine."""
        return [d for d in self.directions if d.status == "unobservable"]

    def statement(self) -> str:
        """The pose pattern and what it determines, in plain words (mm, deg)."""
        spread = math.degrees(self.orientation_spread_rad)
        if self.orientation_spread_rad < SAME_ORIENTATION_RAD:
            text = f"All views share one flange orientation (spread {spread:.2f} deg)"
        else:
            text = f"The flange orientations span ±{spread:.1f} deg"
        major, minor = self.corner_spread_m * 1e3
        if minor < COLLINEAR_RATIO * major:
            text += (
                f"; the weld point was seen along one line of the laser plane (spread "
                f"{major:.1f} mm along it, {minor:.2f} mm across, 1 sigma)"
            )
        else:
            text += f"; the weld point was seen over {major:.1f} x {minor:.1f} mm (1 sigma)"
        missing = self.unobservable
        if not missing:
            worst = float(np.max(self.sigma_m)) * 1e3
            return (
                text + f". The views determine the whole hand-eye (worst direction 1 sigma "
                f"{worst:.3f} mm at a {self.lever_m * 1e3:.0f} mm lever)."
            )
        texts = [d.description for d in missing if _is_rotation(d.vector)]
        shifts = [d.description for d in missing if not _is_rotation(d.vector)]
        if self.point_estimated and len(shifts) > 1:
            same = self.orientation_spread_rad < SAME_ORIENTATION_RAD
            shifts = [
                f"the translation of the sensor in "
                f"{'all three directions' if len(shifts) == 3 else 'two directions'} together "
                "with the same shift of the weld point cannot be determined from these views and "
                f"keeps the initial hand-eye's value: {_shift_reason(same)}, so the two look "
                "alike in every view. To determine it, give the taught point, or tilt the flange "
                "between views by 20 deg or more about two different axes"
            ]
        items = " ".join(f"({k + 1}) {text}." for k, text in enumerate(texts + shifts))
        return (
            text + f". The views determine {6 - len(missing)} of the 6 hand-eye directions; "
            f"not determined: {items}"
        )


def _is_rotation(vector: FloatArray) -> bool:
    """A scaled direction (6,) is mostly a rotation."""
    return float(vector[:3] @ vector[:3]) >= ROTATION_SHARE


def _shift_reason(same_orientation: bool) -> str:
    return (
        "all views share one flange orientation"
        if same_orientation
        else "the flange rotates too little between views"
    )


def _fmt(v: FloatArray) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def _sign_free_angle(a: FloatArray, b: FloatArray) -> float:
    return math.acos(min(1.0, abs(float(a @ b))))


def _describe(
    vector: FloatArray,
    observability_inputs: tuple[float, FloatArray, FloatArray, bool, bool, bool],
    status: str,
    sigma_m: float,
) -> str:
    lever, R_fs, line, collinear, same_orientation, point_estimated = observability_inputs
    verdict = (
        "cannot be determined from these views and keeps the initial hand-eye's value"
        if status == "unobservable"
        else f"is only weakly determined (1 sigma {sigma_m * 1e3:.3f} mm)"
    )
    if _is_rotation(vector):
        theta = vector[:3] / lever
        axis = theta / np.linalg.norm(theta)
        where = ""
        if not point_estimated:
            through = np.cross(theta, R_fs.T @ vector[3:]) / float(theta @ theta)
            where = f" through {_fmt(through * 1e3)} mm"
        if collinear and _sign_free_angle(axis, line) < LINE_ALIGNED_RAD:
            return (
                f"a rotation of the sensor about the line along which the weld point moved "
                f"through the laser plane (direction {_fmt(axis)}{where}, sensor frame) {verdict}: "
                "the point was seen along this one line only"
                + (", from one flange orientation" if same_orientation else "")
                + ", so turning the sensor about it moves no reconstructed point. To determine "
                "it, also move the sensor sideways along the laser line between views (the "
                "point at different x, over 20 mm or more) or tilt the flange by 10-20 deg"
            )
        return (
            f"a rotation of the sensor about {_fmt(axis)}{where} (sensor frame) {verdict}. To "
            "determine it, tilt the flange between views about different axes by 10-20 deg "
            "and see the point at different places along the laser line"
        )
    direction = vector[3:] / np.linalg.norm(vector[3:])
    if point_estimated:
        return (
            f"a translation of the sensor along {_fmt(direction)} (flange frame) together with "
            f"the same shift of the weld point {verdict}: {_shift_reason(same_orientation)}, so "
            "the two look alike in every "
            "view. To determine it, give the taught point, or tilt the flange between views by "
            f"20 deg or more about axes perpendicular to {_fmt(direction)} (flange frame)"
        )
    return (
        f"a translation of the sensor along {_fmt(direction)} (flange frame) {verdict}. To "
        "determine it, tilt the flange between views by 20 deg or more"
    )


def analyse_known_point(
    information_data: ArrayLike,
    corners_xz: ArrayLike,
    T_base_flange: ArrayLike,
    T_flange_sensor: ArrayLike,
    point_estimated: bool,
    config: KnownPointConfig | None = None,
) -> KnownPointObservability:
    """Which hand-eye directions the views determine, in plain words.

    Parameters
    ----------
    information_data : array-like, shape (6, 6)
        Data-only information of ``[θ (rad, sensor axes), ρ (m, flange axes)]``.
    corners_xz : array-like, shape (M, 2)
    T_base_flange : array-like, shape (M, 4, 4)
    T_flange_sensor : array-like, shape (4, 4)
        The estimate the information was formed at.
    point_estimated : bool
    config : KnownPointConfig, optional
        The weak and unobservable thresholds.
    """
    cfg = KnownPointConfig() if config is None else config
    c = np.asarray(corners_xz, dtype=np.float64)
    T = np.asarray(T_base_flange, dtype=np.float64)
    X = np.asarray(T_flange_sensor, dtype=np.float64)
    lever = float(np.median(np.linalg.norm(c, axis=1)))
    _, eigenvectors, sigma = scaled_eigen(np.asarray(information_data, dtype=np.float64), lever)

    R = T[:, :3, :3]
    R_mean = project_to_so3(np.sum(R, axis=0))
    spread = float(np.max(np.linalg.norm(rotvec_from_matrix(R @ R_mean.T), axis=-1)))
    centred = c - c.mean(axis=0)
    _, singular, Vt = np.linalg.svd(centred, full_matrices=False)
    corner_spread = singular / math.sqrt(max(len(c) - 1, 1))
    line = np.array([Vt[0, 0], 0.0, Vt[0, 1]])
    collinear = bool(corner_spread[1] < COLLINEAR_RATIO * corner_spread[0])
    inputs = (lever, X[:3, :3], line, collinear, spread < SAME_ORIENTATION_RAD, point_estimated)

    directions = [
        Direction(d.vector, d.sigma_m, d.status, _describe(d.vector, inputs, d.status, d.sigma_m))
        for d in poor_directions(eigenvectors, sigma, cfg.weak_sigma_m, cfg.unobservable_sigma_m)
    ]
    return KnownPointObservability(
        sigma_m=np.asarray(np.sort(sigma)[::-1], dtype=np.float64),
        lever_m=lever,
        directions=directions,
        orientation_spread_rad=spread,
        corner_spread_m=corner_spread,
        point_estimated=point_estimated,
    )
