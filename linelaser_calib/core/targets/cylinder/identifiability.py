"""Which kinematic parameters a cylinder scan can determine together with the hand-eye.

The joint problem's unknowns are the robot's kinematic parameters (:mod:`.kinematics`), the
hand-eye ``T_flange_sensor`` (6) and the cylinder (axis point 2, direction 2, radius 1).
Each scan point gives one residual, its distance to the cylinder surface. Its derivatives:

- kinematic parameter k, with base twist ``(v_k, ω_k)`` of the flange
  (:func:`~.kinematics.parameter_jacobian`): ``n · (ω_k × X + v_k)``, X the point in the base
  frame and n the outward surface normal at it;
- hand-eye, perturbed in the sensor frame ``T_flange_sensor · exp(δ)``:
  ``n · R_base_sensor (δv + δω × x)``, x the point in the sensor frame;
- axis point moved by ε e (e ⊥ axis): ``-n · e``; direction tilted to a + ε e:
  ``-((X - c) · a)(n · e)``; radius: -1.

Several scans (cylinder placements) share the kinematic parameters and the hand-eye; each
adds its own five cylinder unknowns.

Columns are scaled by the prior 1σ of each unknown (so that a column's size says how much
the data knows against what is known before), then the column-pivoted QR of the stacked
Jacobian orders the unknowns from best to worst determined; an unknown whose pivot falls
below ``rtol`` times the largest is not identifiable, and the right singular vectors of the
smallest singular values name the combinations the data leaves free (for example the
translations along parallel joint axes, which only their sum affects, or the last link,
which the hand-eye absorbs).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from ...geometry import orthonormal_basis
from ...robot.kinematics import KinematicModel, forward_kinematics, parameter_jacobian
from ...types import FloatArray
from .model import Cylinder

#: Names of the hand-eye and cylinder unknowns, after the kinematic parameters.
HAND_EYE_NAMES = tuple(f"hand_eye.{k}" for k in ("tx", "ty", "tz", "rx", "ry", "rz"))
CYLINDER_NAMES = ("cylinder.p1", "cylinder.p2", "cylinder.a1", "cylinder.a2", "cylinder.radius")


@dataclass(frozen=True, eq=False)
class CylinderScan:
    """One cylinder placement scanned by the arm.

    Attributes
    ----------
    q : ndarray, shape (M, n)
        Joint vector of each profile (rad or m).
    points_sensor : list of M arrays (N_i, 3)
        Each profile's points in the sensor frame, m.
    cylinder : Cylinder
        In the base frame, m.
    """

    q: FloatArray
    points_sensor: list[FloatArray]
    cylinder: Cylinder


@dataclass(frozen=True)
class Identifiability:
    """What a set of scans determines.

    Attributes
    ----------
    names : tuple of str
        Every unknown: the kinematic parameters, :data:`HAND_EYE_NAMES`, then
        :data:`CYLINDER_NAMES` per scan (suffixed ``[i]`` when there are several).
    identifiable : tuple of str
        The unknowns the data determines, best first (pivot order).
    unidentifiable : tuple of str
        The others, in pivot order: fix them (priors, nominal values).
    free_combinations : list of dict of str to float
        For each numerically zero singular value, the unit combination (in prior-σ units) of
        unknowns it leaves free, its largest entries only (|weight| > 0.1).
    singular_values : ndarray, shape (U,)
        Of the prior-scaled Jacobian, descending.
    """

    names: tuple[str, ...]
    identifiable: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    free_combinations: list[dict[str, float]]
    singular_values: FloatArray

    @property
    def kinematic_identifiable(self) -> tuple[str, ...]:
        """The identifiable unknowns that are kinematic parameters."""
        return tuple(n for n in self.identifiable if not n.startswith(("hand_eye.", "cylinder.")))


def cylinder_scan_jacobian(
    model: KinematicModel, scan: CylinderScan, T_flange_sensor: ArrayLike
) -> FloatArray:
    """Derivatives of every point's distance to the cylinder surface (module docstring).

    Parameters
    ----------
    model : KinematicModel
    scan : CylinderScan
    T_flange_sensor : array_like, shape (4, 4)

    Returns
    -------
    ndarray, shape (sum N_i, P + 6 + 5)
        Columns: the kinematic parameters, the hand-eye, the cylinder (unscaled: m per m
        or per rad).
    """
    T_fs = np.asarray(T_flange_sensor, dtype=np.float64)
    T_bf = forward_kinematics(model, scan.q)
    J_kin = parameter_jacobian(model, scan.q)
    cylinder = scan.cylinder
    a = cylinder.direction / np.linalg.norm(cylinder.direction)
    e1, e2 = orthonormal_basis(a)
    rows = []
    for k, x in enumerate(scan.points_sensor):
        T_bs = T_bf[k] @ T_fs
        X = x @ T_bs[:3, :3].T + T_bs[:3, 3]
        v = X - cylinder.point
        along = v @ a
        radial = v - np.outer(along, a)
        n = radial / np.linalg.norm(radial, axis=1, keepdims=True)
        kin = np.einsum("ni,ik->nk", n, J_kin[k, :3]) + np.einsum(
            "ni,ik->nk", np.cross(X, n), J_kin[k, 3:]
        )
        m = n @ T_bs[:3, :3]
        hand_eye = np.hstack([m, np.cross(x, m)])
        cyl = np.stack(
            [-n @ e1, -n @ e2, -along * (n @ e1), -along * (n @ e2), -np.ones(len(x))], axis=1
        )
        rows.append(np.hstack([kin, hand_eye, cyl]))
    return np.vstack(rows)


def cylinder_identifiability(
    model: KinematicModel,
    scans: Sequence[CylinderScan],
    T_flange_sensor: ArrayLike,
    *,
    sigma_length_m: float = 1e-3,
    sigma_angle_rad: float = 1e-3,
    rtol: float = 1e-6,
) -> Identifiability:
    """The identifiable kinematic, hand-eye and cylinder unknowns of cylinder scans.

    The scans share the robot and the hand-eye; each has its own cylinder.

    Parameters
    ----------
    model : KinematicModel
    scans : sequence of CylinderScan
    T_flange_sensor : array_like, shape (4, 4)
    sigma_length_m, sigma_angle_rad : float
        Column scales: prior 1σ of every length (m) and angle (rad) unknown.
    rtol : float
        An unknown whose QR pivot is below ``rtol`` times the largest is not identifiable.
    """
    shared = len(model.parameter_names) + len(HAND_EYE_NAMES)
    blocks = [cylinder_scan_jacobian(model, scan, T_flange_sensor) for scan in scans]
    per_scan = len(CYLINDER_NAMES)
    J = np.zeros((sum(len(b) for b in blocks), shared + per_scan * len(scans)))
    row = 0
    for i, block in enumerate(blocks):
        J[row : row + len(block), :shared] = block[:, :shared]
        J[row : row + len(block), shared + per_scan * i : shared + per_scan * (i + 1)] = block[
            :, shared:
        ]
        row += len(block)
    cylinder_is_length = [True, True, False, False, True] * len(scans)
    is_length = np.concatenate(
        [model.parameter_is_length, [True] * 3, [False] * 3, cylinder_is_length]
    )
    J = J * np.where(is_length, sigma_length_m, sigma_angle_rad)
    suffix = [f"[{i}]" if len(scans) > 1 else "" for i in range(len(scans))]
    names = (
        *model.parameter_names,
        *HAND_EYE_NAMES,
        *(name + tag for tag in suffix for name in CYLINDER_NAMES),
    )

    _, R, pivots = scipy.linalg.qr(J, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(R))
    rank = int(np.sum(diagonal > rtol * diagonal[0]))
    order = [names[i] for i in pivots]
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    free = []
    for vector in Vt[rank:]:
        big = np.flatnonzero(np.abs(vector) > 0.1)
        free.append({names[i]: float(vector[i]) for i in big[np.argsort(-np.abs(vector[big]))]})
    return Identifiability(names, tuple(order[:rank]), tuple(order[rank:]), free, s)
