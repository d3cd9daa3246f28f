"""Which hand-eye motions the flange poses determine, and what to add when they do not.

The cylinder's refinement (:mod:`linelaser_calib.core.targets.cylinder.refine`) hands over
the marginal information matrix of the hand-eye, that is the Gauss-Newton information after
the cylinder axis, the radius and the per-sample pose corrections have been eliminated (Schur
complement). Its parameters are ``[θ (3), ρ (3)]``: small rotation angles θ (rad) about the
sensor axes (``R = R̂ · Exp(θ)``) and a translation ρ (m) in the flange frame (``t = t̂ + ρ``).

To compare rotations with translations, rotations are scaled by a lever length L (the
stand-off, about the distance of the profile points from the sensor): a rotation of θ rad
moves the profile by about θ·L m. In these units each eigen-direction of the information
has a predicted 1σ in metres, ``1 / sqrt(eigenvalue)``. A direction whose 1σ exceeds
``unobservable_sigma_m`` is unobservable (:class:`~.errors.DegenerateError`), one above
``weak_sigma_m`` is weak (a warning).

What makes a direction unobservable (worked out from the cylinder's symmetries, translation
along its axis and rotation about it, and verified numerically in ``test/test_refine.py``):

(a) all flange poses have the same orientation: a change of the hand-eye translation moves
    every profile by the same base-frame vector, which the cylinder's position absorbs; all
    three translations are unobservable, the rotation stays observable if the sensor
    translates across the axis.
(b) the flange only translates along the cylinder axis: every profile is the same curve, so
    only the cylinder as seen from the flange is known; all three translations and the
    rotation about the cylinder axis (as seen from the sensor) are unobservable.
(c) the flange only rotates about the cylinder axis (orbits it): again every profile is the
    same curve, but now the cylinder is fixed in the flange frame; the translation along
    the cylinder axis and the rotation about it are unobservable.

Motions that fix them: rotating the flange (about axes perpendicular to the unobservable
translation) for translations; translating the sensor across the cylinder axis and changing
the cut angle between the laser plane and the axis for rotations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .errors import DegenerateError, InputError
from .geometry import FloatArray, project_to_so3, rotvec_from_matrix

#: A direction within this angle of the cylinder axis is described as "along the axis", rad.
AXIS_ALIGNED_RAD = float(np.deg2rad(25.0))
#: A rotation line closer than this to the cylinder axis is "the cylinder axis itself", m.
ON_AXIS_M = 5e-3
#: A direction whose rotation part (scaled) carries at least this share is a rotation.
ROTATION_SHARE = 0.2
#: Flange orientations spanning less than this are "the same orientation", rad.
SAME_ORIENTATION_RAD = float(np.deg2rad(2.0))


@dataclass(frozen=True)
class ObservabilityConfig:
    """Thresholds of the observability check.

    Attributes
    ----------
    weak_sigma_m : float
        A direction whose predicted 1σ (m; rotations times the lever) exceeds this is weak,
        and a warning names the motion that would fix it. Default 0.2 mm, four times the
        translation accuracy a good pose set reaches at the paper's noise (0.05 mm).
    unobservable_sigma_m : float
        Above this the direction is unobservable and the refinement raises
        :class:`~.errors.DegenerateError`. Default 5 mm: worse than the seed solver.
    lever_m : float or None
        Length that converts rotations to displacements, m; None takes the median distance
        of the profile points from the sensor origin.
    """

    weak_sigma_m: float = 2e-4
    unobservable_sigma_m: float = 5e-3
    lever_m: float | None = None

    def __post_init__(self) -> None:
        if not 0.0 < self.weak_sigma_m < self.unobservable_sigma_m:
            raise InputError(
                "observability thresholds must satisfy 0 < weak_sigma_m < unobservable_sigma_m, "
                f"got {self.weak_sigma_m} m and {self.unobservable_sigma_m} m"
            )
        if self.lever_m is not None and not self.lever_m > 0.0:
            raise InputError(f"lever_m must be a positive length in m or None, got {self.lever_m}")


@dataclass(frozen=True)
class PoseGeometry:
    """What the description of a missing motion needs to know about the poses.

    Attributes
    ----------
    R_flange_sensor : ndarray, shape (3, 3)
        Hand-eye rotation (to relate sensor-frame rotations to flange-frame translations).
    axis_in_sensor : ndarray, shape (3,)
        Cylinder axis direction seen from the sensor (mean over poses, unit).
    axis_point_in_sensor : ndarray, shape (3,)
        Mean over poses of the axis point nearest the sensor origin, sensor frame, m.
    axis_in_flange : ndarray, shape (3,)
        Cylinder axis direction in the flange frame (mean over poses, unit).
    orientation_spread_rad : float
        Largest angle between a flange orientation and their mean, rad.
    rotation_about_axis_share : float
        Of the flange's rotations away from the mean orientation, the share (0..1, of the
        total squared angle) that is about the cylinder axis.
    along_axis_m, across_axis_m : float
        Peak-to-peak extent of the sensor origins along the cylinder axis, and the largest
        peak-to-peak extent across it, m.
    """

    R_flange_sensor: FloatArray
    axis_in_sensor: FloatArray
    axis_point_in_sensor: FloatArray
    axis_in_flange: FloatArray
    orientation_spread_rad: float
    rotation_about_axis_share: float
    along_axis_m: float
    across_axis_m: float

    def summary(self) -> str:
        """One sentence describing the pose set, in mm and degrees."""
        spread = np.rad2deg(self.orientation_spread_rad)
        text = f"the flange orientations span ±{spread:.1f} deg"
        if self.orientation_spread_rad < SAME_ORIENTATION_RAD:
            text += " (the flange hardly rotates)"
        elif self.rotation_about_axis_share > 0.95:
            text += " (rotating only about the cylinder axis)"
        return (
            f"{text}; the sensor positions span {self.along_axis_m * 1e3:.1f} mm along the "
            f"cylinder axis and {self.across_axis_m * 1e3:.1f} mm across it"
        )


def pose_geometry(
    T_base_flange: FloatArray, T_flange_sensor: FloatArray, point: FloatArray, direction: FloatArray
) -> PoseGeometry:
    """Summarise a pose set relative to the cylinder axis.

    Parameters
    ----------
    T_base_flange : ndarray, shape (M, 4, 4)
    T_flange_sensor : ndarray, shape (4, 4)
    point, direction : ndarray, shape (3,)
        A point on the cylinder axis (m) and its unit direction, base frame.
    """
    R = T_base_flange[:, :3, :3]
    R_fs = T_flange_sensor[:3, :3]
    axis_flange = np.einsum("mji,j->mi", R, direction)
    sign = np.sign(axis_flange @ axis_flange[0])
    axis_flange = np.sum(axis_flange * sign[:, None], axis=0)
    axis_flange /= np.linalg.norm(axis_flange)
    R_base_sensor = R @ R_fs
    origins = np.einsum("mij,j->mi", R, T_flange_sensor[:3, 3]) + T_base_flange[:, :3, 3]
    w = point - origins
    nearest = w - np.outer(w @ direction, direction)
    R_mean = project_to_so3(np.sum(R, axis=0))
    rotvecs = rotvec_from_matrix(R @ R_mean.T)
    angles_sq = np.sum(rotvecs**2, axis=1)
    total = float(np.sum(angles_sq))
    about_axis = float(np.sum((rotvecs @ direction) ** 2)) / total if total > 0.0 else 0.0
    along = origins @ direction
    across = origins - np.outer(along, direction)
    centred = across - across.mean(axis=0)
    _, _, Vt = np.linalg.svd(centred, full_matrices=False)
    return PoseGeometry(
        R_flange_sensor=R_fs,
        axis_in_sensor=R_fs.T @ axis_flange,
        axis_point_in_sensor=np.mean(np.einsum("mji,mj->mi", R_base_sensor, nearest), axis=0),
        axis_in_flange=axis_flange,
        orientation_spread_rad=float(np.sqrt(np.max(angles_sq))),
        rotation_about_axis_share=about_axis,
        along_axis_m=float(np.ptp(along)),
        across_axis_m=float(np.ptp(centred @ Vt[0])),
    )


@dataclass(frozen=True)
class Direction:
    """One weak or unobservable hand-eye direction.

    Attributes
    ----------
    vector : ndarray, shape (6,)
        Unit vector in scaled units: rotation times the lever about the sensor x, y, z axes,
        then translation along the flange x, y, z axes.
    sigma_m : float
        Predicted 1σ along it, m (inf when the information is zero).
    status : str
        ``weak`` or ``unobservable``.
    description : str
        The motion of the hand-eye and the missing robot motion that would fix it.
    """

    vector: FloatArray
    sigma_m: float
    status: str
    description: str


@dataclass(frozen=True)
class Observability:
    """Eigen-analysis of the hand-eye's marginal information, in scaled units.

    Attributes
    ----------
    eigenvalues : ndarray, shape (6,)
        Ascending, 1/m² (rotations scaled by the lever).
    eigenvectors : ndarray, shape (6, 6)
        Columns, in the units of :attr:`Direction.vector`.
    sigma_m : ndarray, shape (6,)
        Predicted 1σ per eigen-direction, m (inf for a zero eigenvalue).
    lever_m : float
    directions : list of Direction
        The weak and unobservable directions, unobservable first.
    pose_summary : str
    unobservable_sigma_m : float
        The threshold the directions were judged by, m.
    """

    eigenvalues: FloatArray
    eigenvectors: FloatArray
    sigma_m: FloatArray
    lever_m: float
    directions: list[Direction]
    pose_summary: str
    unobservable_sigma_m: float

    @property
    def unobservable(self) -> list[Direction]:
        """Directions the poses cannot determine."""
        return [d for d in self.directions if d.status == "unobservable"]

    @property
    def warnings(self) -> list[str]:
        """One warning per weak direction."""
        return [
            f"weak hand-eye direction (predicted 1 sigma {d.sigma_m * 1e3:.2f} mm): "
            f"{d.description}; {self.pose_summary}"
            for d in self.directions
            if d.status == "weak"
        ]

    def raise_if_unobservable(self) -> None:
        """Raise DegenerateError naming the missing motions, if any direction is unobservable."""
        missing = self.unobservable
        if not missing:
            return
        items = " ".join(f"({k + 1}) {d.description}." for k, d in enumerate(missing))
        raise DegenerateError(
            f"the flange poses cannot determine the hand-eye: {len(missing)} direction(s) "
            f"have a predicted 1 sigma above {self.unobservable_sigma_m * 1e3:.0f} mm. {items} "
            f"Here {self.pose_summary}. Add such poses and calibrate again."
        )


def _fmt(v: FloatArray) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def _angle_to(v: FloatArray, axis: FloatArray) -> float:
    """Sign-free angle between two unit vectors, rad."""
    return float(np.arccos(np.clip(abs(float(v @ axis)), 0.0, 1.0)))


def describe_direction(
    vector: FloatArray, lever_m: float, geometry: PoseGeometry, status: str = "unobservable"
) -> str:
    """Plain words for a hand-eye direction and the robot motion that would determine it.

    A direction with a rotation part is a rotation about a line (plus, for a screw, a
    translation along it); the line follows from the rotation θ and the translation ρ: it
    runs along θ through the sensor-frame point (θ × R_fsᵀρ) / |θ|².

    Parameters
    ----------
    vector : ndarray, shape (6,)
        Unit direction in scaled units (see :class:`Direction`).
    lever_m : float
        The length the rotation part was scaled by, m.
    geometry : PoseGeometry
    status : str
        ``unobservable`` ("cannot be seen") or ``weak`` ("can hardly be seen").
    """
    cannot = "cannot" if status == "unobservable" else "can hardly"
    theta = vector[:3] / lever_m
    rho_sensor = geometry.R_flange_sensor.T @ vector[3:]
    if float(vector[:3] @ vector[:3]) >= ROTATION_SHARE:
        axis = theta / np.linalg.norm(theta)
        through = np.cross(theta, rho_sensor) / float(theta @ theta)
        offset = through - geometry.axis_point_in_sensor
        offset -= float(offset @ geometry.axis_in_sensor) * geometry.axis_in_sensor
        parallel = _angle_to(axis, geometry.axis_in_sensor) < AXIS_ALIGNED_RAD
        text = (
            f"rotation of the sensor about a line along {_fmt(axis)} through "
            f"{_fmt(through * 1e3)} mm (sensor frame)"
        )
        if parallel and float(np.linalg.norm(offset)) < ON_AXIS_M:
            text += ", i.e. about the cylinder axis itself"
        elif parallel:
            text += ", i.e. parallel to the cylinder axis"
        return (
            text + f", {cannot} be seen because the profiles look alike: translate the sensor "
            "across the cylinder axis between poses and change the cut angle between the laser "
            "plane and the axis (spread it over 40-75 deg, both signs), rather than only "
            "sliding along or orbiting the axis"
        )
    direction = vector[3:] / np.linalg.norm(vector[3:])
    text = f"translation of the sensor along {_fmt(direction)} (flange frame)"
    if _angle_to(direction, geometry.axis_in_flange) < AXIS_ALIGNED_RAD:
        return (
            text + f", i.e. along the cylinder axis, {cannot} be told from sliding the cylinder "
            "along itself: tilt the flange between poses so that the cylinder axis changes "
            "direction relative to the flange by at least 20 deg (e.g. cut angles spread over "
            "40-75 deg with both signs)"
        )
    return (
        text + f", {cannot} be told from a shift of the cylinder: rotate the flange between poses "
        f"by at least 20 deg about axes perpendicular to {_fmt(direction)}"
    )


def _canonical_basis(V: FloatArray) -> FloatArray:
    """Re-express a subspace basis (6, k) so that each column is mostly rotation or mostly
    translation (SVD of its rotation rows); the columns stay orthonormal."""
    _, _, Qt = np.linalg.svd(V[:3], full_matrices=True)
    return np.asarray(V @ Qt.T)


def scaled_eigen(
    information: FloatArray, lever_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Eigen-decomposition of a hand-eye information matrix in length units.

    Parameters
    ----------
    information : ndarray, shape (6, 6)
        Information of ``[θ (rad, sensor axes), ρ (m, flange axes)]``.
    lever_m : float
        Length converting rotation (rad) to displacement (m).

    Returns
    -------
    eigenvalues : ndarray, shape (6,), ascending
    eigenvectors : ndarray, shape (6, 6)
        Columns in scaled units (rotation times the lever, then translation).
    sigma_m : ndarray, shape (6,)
        1-sigma along each eigenvector, m; inf where the information is a numerical zero.
    """
    scale = np.array([lever_m] * 3 + [1.0] * 3)
    scaled = np.asarray(information, dtype=np.float64) / np.outer(scale, scale)
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (scaled + scaled.T))
    # Eigenvalues below eps * largest are numerical zeros: the direction has no information.
    floor = float(np.finfo(float).eps) * max(float(eigenvalues[-1]), 0.0) * 6.0
    sigma = np.where(eigenvalues > floor, 1.0 / np.sqrt(np.maximum(eigenvalues, floor)), np.inf)
    return eigenvalues, eigenvectors, np.asarray(sigma, dtype=np.float64)


class PoorDirection(NamedTuple):
    """A hand-eye direction (6,) in scaled units, its 1-sigma (m) and ``weak``/``unobservable``."""

    vector: FloatArray
    sigma_m: float
    status: str


def poor_directions(
    eigenvectors: FloatArray, sigma_m: FloatArray, weak_sigma_m: float, unobservable_sigma_m: float
) -> list[PoorDirection]:
    """Unobservable (1-sigma above ``unobservable_sigma_m``) and weak directions, unobservable
    first, each subspace re-expressed so that a direction is mostly rotation or mostly
    translation (:func:`_canonical_basis`)."""
    found: list[PoorDirection] = []
    for status, low, high in (
        ("unobservable", unobservable_sigma_m, np.inf),
        ("weak", weak_sigma_m, unobservable_sigma_m),
    ):
        chosen = (sigma_m > low) & (sigma_m <= high)
        if not np.any(chosen):
            continue
        basis = eigenvectors[:, chosen]
        for v in _canonical_basis(basis).T:
            weights = (basis.T @ v) ** 2
            share = weights > 1e-12
            variance = float(np.sum(weights[share] * sigma_m[chosen][share] ** 2))
            found.append(PoorDirection(v, float(np.sqrt(variance)), status))
    return found


def analyse_observability(
    information: FloatArray,
    lever_m: float,
    geometry: PoseGeometry,
    config: ObservabilityConfig,
) -> Observability:
    """Eigen-analysis of the hand-eye's marginal information and plain-words diagnosis.

    Parameters
    ----------
    information : ndarray, shape (6, 6)
        Marginal information of ``[θ (rad, sensor axes), ρ (m, flange axes)]``.
    lever_m : float
        Length converting rotation (rad) to displacement (m).
    geometry : PoseGeometry
    config : ObservabilityConfig
    """
    eigenvalues, eigenvectors, sigma = scaled_eigen(information, lever_m)
    directions = [
        Direction(
            d.vector, d.sigma_m, d.status, describe_direction(d.vector, lever_m, geometry, d.status)
        )
        for d in poor_directions(
            eigenvectors, sigma, config.weak_sigma_m, config.unobservable_sigma_m
        )
    ]
    return Observability(
        eigenvalues=eigenvalues,
        eigenvectors=eigenvectors,
        sigma_m=np.asarray(sigma, dtype=np.float64),
        lever_m=float(lever_m),
        directions=directions,
        pose_summary=geometry.summary(),
        unobservable_sigma_m=config.unobservable_sigma_m,
    )
