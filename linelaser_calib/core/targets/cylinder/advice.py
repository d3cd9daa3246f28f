"""What another placement of the cylinder would add to a joint kinematic calibration.

A joint calibration from one placement leaves some kinematic combinations free
(:mod:`.identifiability`). Whether another placement determines them is answered on the
scans themselves: the target and every view of it are moved together by a rigid motion M of
the base frame (the cylinder moved and tilted, each flange pose ``M · T_base_flange``, so
every profile stays as recorded), the arm's joint vectors for the moved flange poses come from
inverse kinematics (poses out of reach are left out), and the identifiability of the scans
taken so far plus the moved copy is compared with that of the scans alone:

- the number of kinematic parameters determined, and which ones the move adds;
- how much better the worst-determined combination of those determined now becomes: with H
  the kinematic information (hand-eye and cylinders marginalised, columns in prior-σ units)
  and V an orthonormal basis of the combinations determined now, the smallest eigenvalue of
  ``Vᵀ H V`` before and after; the square root of their ratio is the factor by which its 1σ
  shrinks. The same placement recorded again (the scans doubled) gives the baseline √2.

Moves tried (about the cylinder's point, in the base frame): sideways and closer by 0.3 m and
0.15 m, tilted by 20° about the horizontal axes, and sideways with a tilt. Placements are
added greedily while one adds parameters, which gives the number of placements needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...geometry import FloatArray, exp_so3
from ...robot.joint_calibration import (
    JointCalibrationConfig,
    KinematicIdentifiability,
    KinematicSetup,
    kinematic_identifiability,
)
from ...robot.kinematics import KinematicModel, forward_kinematics, inverse_kinematics
from ..base import AdviceScan, ResultSection
from .identifiability import CylinderScan, cylinder_scan_jacobian
from .model import Cylinder
from .section import CylinderSection

#: Share of the views that the arm must reach for a move to be proposed.
MIN_REACHED = 0.6
#: Sideways and closer shifts (m) and the tilt (rad) of the moves tried.
SHIFT_M = 0.3
TILT_RAD = float(np.deg2rad(20.0))
#: Most placements proposed in all.
MAX_PLACEMENTS = 3
#: The joint solve's default priors and threshold.
DEFAULT_JOINT_CONFIG = JointCalibrationConfig()


@dataclass(frozen=True)
class PlacementMove:
    """A rigid motion of the target (with the views of it) in the base frame.

    Attributes
    ----------
    label : str
        What to do, in words (mm and degrees labelled).
    T_motion : ndarray, shape (4, 4)
        The motion, base frame (m).
    """

    label: str
    T_motion: FloatArray


@dataclass(frozen=True)
class MoveOutcome:
    """What one move adds to the scans so far.

    Attributes
    ----------
    move : PlacementMove
    identifiable : int
        Kinematic parameters determined with the moved scans added.
    added : int
        How many more than now.
    reached : float
        Share of the views the arm reaches at the moved placement.
    gain : float
        Factor by which the 1σ of the worst-determined combination of those determined now
        shrinks (module docstring).
    """

    move: PlacementMove
    identifiable: int
    added: int
    reached: float
    gain: float


@dataclass(frozen=True)
class PlacementAdvice:
    """Whether more placements of the cylinder determine more of the robot's kinematics.

    Attributes
    ----------
    n_parameters : int
        Kinematic parameters of the model.
    placements : int
        Placements scanned so far.
    identifiable : int
        Kinematic parameters the scans so far determine.
    free : list of dict of str to float
        The kinematic combinations they leave free (prior-σ units, largest entries).
    best : MoveOutcome or None
        The most useful move the arm reaches (most parameters added, then largest gain).
    needed : int
        Placements in all that determine every parameter further placements can (greedy).
    still_free : list of dict of str to float
        Combinations free even with ``needed`` placements: no cylinder placement fixes them.
    """

    n_parameters: int
    placements: int
    identifiable: int
    free: list[dict[str, float]]
    best: MoveOutcome | None
    needed: int
    still_free: list[dict[str, float]]

    def text(self) -> str:
        """The advice in words, with the numbers."""
        now = (
            f"{self.placements} placement{'s' if self.placements > 1 else ''} of the cylinder "
            f"determine{'s' if self.placements == 1 else ''} {self.identifiable} of "
            f"{self.n_parameters} kinematic parameters"
        )
        if self.best is None:
            return now + "; no other placement the arm reaches with these views was found"
        best = self.best
        if best.added:
            return (
                f"{now}; {self.needed} placements are needed: {best.move.label} and record "
                f"again (the arm reaches {best.reached:.0%} of these views there), which "
                f"determines {best.added} more and the worst-determined of the others "
                f"{best.gain:.1f} times better (the same placement recorded again: 1.4 times); "
                "calibrate the recordings together, with the robot model ({setting:kinematics})"
            )
        return (
            f"{now}; another placement determines no further one: the "
            f"{self.n_parameters - self.identifiable} left free are what no cylinder of "
            "unknown placement fixes (the base's turn and height: add a reference with known "
            "base coordinates, e.g. {setting:target} known_point; the last link's: the hand-eye "
            "absorbs them; lengths along parallel joint axes: only their sum counts). Another "
            f"placement makes the worst-determined parameter {best.gain:.1f} times better "
            f"({best.move.label}; the same placement recorded again: 1.4 times)"
        )


def candidate_moves(cylinder: Cylinder) -> list[PlacementMove]:
    """The moves tried, about the cylinder's point (module docstring)."""
    c = np.asarray(cylinder.point, dtype=np.float64)
    out = np.array([c[0], c[1], 0.0])
    out = out / np.linalg.norm(out) if np.linalg.norm(out) > 1e-6 else np.array([1.0, 0, 0])
    side = np.cross([0.0, 0.0, 1.0], out)

    def motion(rotvec: FloatArray, shift: FloatArray) -> FloatArray:
        T = np.eye(4)
        T[:3, :3] = exp_so3(rotvec)
        T[:3, 3] = c + shift - T[:3, :3] @ c
        return T

    zero = np.zeros(3)
    tilt = np.rad2deg(TILT_RAD)
    moves = [
        (f"move the cylinder sideways by {SHIFT_M * 1e3:.0f} mm", zero, SHIFT_M * side),
        (f"move the cylinder sideways by -{SHIFT_M * 1e3:.0f} mm", zero, -SHIFT_M * side),
        (
            f"move the cylinder {SHIFT_M * 500:.0f} mm closer to the robot",
            zero,
            -0.5 * SHIFT_M * out,
        ),
        (f"tilt the cylinder by {tilt:.0f} deg towards the robot", TILT_RAD * side, zero),
        (f"tilt the cylinder by {tilt:.0f} deg sideways", TILT_RAD * out, zero),
        (
            f"move the cylinder sideways by {SHIFT_M * 1e3:.0f} mm and tilt it by {tilt:.0f} deg",
            TILT_RAD * out,
            SHIFT_M * side,
        ),
    ]
    return [PlacementMove(label, motion(r, s)) for label, r, s in moves]


def moved_scan(
    model: KinematicModel, scan: CylinderScan, move: PlacementMove
) -> tuple[CylinderScan, float]:
    """The scan with the cylinder and its views moved, the views the arm reaches only, and the
    share reached."""
    M = move.T_motion
    targets = M @ forward_kinematics(model, scan.q)
    picks = np.unique(np.linspace(0, len(scan.q) - 1, 2).astype(int))
    solved = inverse_kinematics(
        model, targets, scan.q[picks], iterations=25, tolerance_m=1e-7, tolerance_rad=1e-7
    )
    ok = np.flatnonzero(solved.converged)
    cylinder = Cylinder(
        M[:3, :3] @ scan.cylinder.point + M[:3, 3],
        M[:3, :3] @ scan.cylinder.direction,
        scan.cylinder.radius,
    )
    points = [scan.points_sensor[k] for k in ok]
    return CylinderScan(solved.q[ok], points, cylinder), len(ok) / max(len(scan.q), 1)


def _information(
    model: KinematicModel, scans: Sequence[CylinderScan], T_flange_sensor: FloatArray
) -> FloatArray:
    """Information of [hand-eye (6), each cylinder (5), kinematic parameters (P)] from the
    point-to-surface distances (unit noise)."""
    P = len(model.parameter_names)
    G = 6 + 5 * len(scans)
    H = np.zeros((G + P, G + P))
    for i, scan in enumerate(scans):
        J = cylinder_scan_jacobian(model, scan, T_flange_sensor)
        columns = np.concatenate([G + np.arange(P), np.arange(6), 6 + 5 * i + np.arange(5)])
        H[np.ix_(columns, columns)] += J.T @ J
    return H


def _identifiability(
    model: KinematicModel,
    scans: Sequence[CylinderScan],
    T_flange_sensor: FloatArray,
    config: JointCalibrationConfig,
) -> tuple[KinematicIdentifiability, FloatArray]:
    """The joint solve's identifiability criterion on the scans, and the kinematic
    information (P, P) in prior-σ units (hand-eye and cylinders marginalised)."""
    H = _information(model, scans, T_flange_sensor)
    G = 6 + 5 * len(scans)
    sigma = config.prior_sigma(model)
    found = kinematic_identifiability(H, G, model.parameter_names, sigma, config.rtol)
    S = H[G:, G:] - H[G:, :G] @ np.linalg.pinv(H[:G, :G], hermitian=True) @ H[:G, G:]
    return found, np.asarray(S * np.outer(sigma, sigma))


def _weakest(H: FloatArray, basis: FloatArray) -> float:
    """Smallest information of a unit combination in span(basis)."""
    return float(np.linalg.eigvalsh(basis.T @ H @ basis)[0])


def placement_advice(
    model: KinematicModel,
    scans: Sequence[CylinderScan],
    T_flange_sensor: FloatArray,
    config: JointCalibrationConfig = DEFAULT_JOINT_CONFIG,
) -> PlacementAdvice:
    """Whether, and where, another cylinder placement determines more kinematic parameters.

    Parameters
    ----------
    model : KinematicModel
        The (corrected or nominal) model.
    scans : sequence of CylinderScan
        The placements scanned so far (a few points per profile suffice).
    T_flange_sensor : ndarray, shape (4, 4)
    config : JointCalibrationConfig
        The joint solve's priors and threshold, so that "determined" means what it means
        there (:func:`~.joint_calibration.kinematic_identifiability`).
    """
    scans = list(scans)
    now, H_now = _identifiability(model, scans, T_flange_sensor, config)
    count = len(now.identifiable)
    eigenvalues, vectors = np.linalg.eigh(H_now)
    basis = vectors[:, len(eigenvalues) - count :]
    weakest_now = _weakest(H_now, basis)

    def evaluate(taken: list[CylinderScan], determined: int) -> list[MoveOutcome]:
        outcomes = []
        for move in candidate_moves(taken[0].cylinder):
            moved, reached = moved_scan(model, taken[0], move)
            if reached < MIN_REACHED:
                continue
            found, H = _identifiability(model, [*taken, moved], T_flange_sensor, config)
            gain = float(np.sqrt(max(_weakest(H, basis), 0.0) / weakest_now))
            outcomes.append(
                MoveOutcome(
                    move,
                    len(found.identifiable),
                    len(found.identifiable) - determined,
                    reached,
                    gain,
                )
            )
        return outcomes

    def most_useful(outcomes: list[MoveOutcome]) -> MoveOutcome | None:
        return max(outcomes, key=lambda o: (o.added, o.gain), default=None)

    best = most_useful(evaluate(scans, count))
    taken, determined, step = list(scans), count, best
    while step is not None and step.added > 0 and len(taken) < MAX_PLACEMENTS:
        taken.append(moved_scan(model, taken[0], step.move)[0])
        determined = step.identifiable
        step = most_useful(evaluate(taken, determined))
    final, _ = _identifiability(model, taken, T_flange_sensor, config)
    return PlacementAdvice(
        n_parameters=len(model.parameter_names),
        placements=len(scans),
        identifiable=count,
        free=now.free_combinations,
        best=best,
        needed=len(taken),
        still_free=final.free_combinations,
    )


def thinned(scan: CylinderScan, per_profile: int) -> CylinderScan:
    """The scan with at most ``per_profile`` evenly spaced points per profile (for speed)."""
    points = [p[:: max(1, len(p) // per_profile)][:per_profile] for p in scan.points_sensor]
    return replace(scan, points_sensor=points)


def _advice_scan(
    profiles: Sequence[Any],
    setup: KinematicSetup,
    T_flange_sensor: FloatArray,
    cylinder: Cylinder,
) -> CylinderScan:
    """One placement for the advice: its joint vectors and up to 30 points of each profile
    (objects with ``stamp_ns`` and sensor-frame ``points`` (N, 3), m) within 0.5 mm of its
    cylinder (mapped with ``setup``'s model)."""
    q = setup.joint_positions([p.stamp_ns for p in profiles])
    T = forward_kinematics(setup.model, q) @ T_flange_sensor
    points = []
    for profile, T_bs in zip(profiles, T, strict=True):
        x = np.asarray(
            profile.points[np.all(np.isfinite(profile.points), axis=1)], dtype=np.float64
        )
        v = x @ T_bs[:3, :3].T + T_bs[:3, 3] - cylinder.point
        radial = v - np.outer(v @ cylinder.direction, cylinder.direction)
        points.append(x[np.abs(np.linalg.norm(radial, axis=1) - cylinder.radius) < 5e-4])
    return thinned(CylinderScan(q, points, cylinder), 30)


class CylinderPlacementAdviser:
    """:class:`~linelaser_calib.core.targets.base.PlacementAdviser` of the cylinder: the
    placement is the :class:`~.model.Cylinder` (base frame, m)."""

    def placement_of(self, section: ResultSection) -> Cylinder | None:
        """The cylinder of a cylinder result section; None for another section."""
        return section.cylinder if isinstance(section, CylinderSection) else None

    def placement_from_numbers(
        self, numbers: Sequence[float], radius_m: float | None
    ) -> Cylinder | None:
        """From ``px,py,pz,dx,dy,dz`` (a point on the axis and its direction, m) and the
        radius; None without the radius."""
        if radius_m is None:
            return None
        direction = np.array(numbers[3:6]) / np.linalg.norm(numbers[3:6])
        return Cylinder(np.array(numbers[:3]), direction, radius_m)

    def advise(
        self,
        scans: Sequence[AdviceScan],
        model: KinematicModel,
        T_flange_sensor: FloatArray,
        clock_offset_s: float = 0.0,
    ) -> str:
        """:func:`placement_advice` in words, on up to 30 points of each profile within
        0.5 mm of its placement's cylinder.

        Raises
        ------
        InputError
            A model joint the states do not name, or a profile outside the joint-state
            stream.
        """
        setup = KinematicSetup(model, scans[0][1], clock_offset_s)
        taken = [
            _advice_scan(
                profiles, KinematicSetup(model, states, clock_offset_s), T_flange_sensor, placed
            )
            for profiles, states, placed in scans
        ]
        return placement_advice(model, taken, T_flange_sensor, setup.config).text()
