"""The cylinder paper's centre-to-axis model (eq. 6-12).

Every ellipse centre ``(x_c, z_c)`` measured in the sensor frame lies on the cylinder axis.
Mapped into the base frame through the flange pose and the unknown hand-eye (eq. 6),

    O_j = T_base_flange_j · T_flange_sensor · [x_c, 0, z_c, 1]ᵀ
        = R_j (x_c a1 + z_c a3 + t) + p_j,

so only the first and third rotation columns ``a1``, ``a3`` and the translation ``t`` of the
hand-eye matter. With a point ``P`` and a direction ``N`` of the axis, the 15-vector of
unknowns is (eq. 10)

    x = [a11, a21, a31, a13, a23, a33, t1, t2, t3, x0, y0, z0, m, l, n]
      = [a1 (0:3), a3 (3:6), t (6:9), P (9:12), N (12:15)],

the cost is f(x) = Σ_j d_j² with d_j² = |O_j − P|² − (N·(O_j − P))² (eq. 8-9, 12), and the
constraints are h(x) = [|a1|² − 1, |a3|² − 1, |N|² − 1] = 0 (eq. 11).

Units
-----
The public API takes SI data (centres in m, ``T_base_flange`` translations in m). A
:class:`CentreAxisProblem` stores the data in an internal length unit ``unit_m`` (metres per
unit) and every x, f and gradient it handles is in that unit: t and P in units, f in units².
The paper works in mm (``unit_m = 1e-3``); its f is in mm², so its thresholds (ψ = 0.5 mm²,
success f < 1e-3 mm², divergence f > 1e3 mm²) are areas: divide an area in m² by
``unit_m ** 2`` to compare it with f. By default the unit is the RMS norm of the centres
(the sensor stand-off), which makes the hand-eye rotation and translation blocks of the
Hessian of comparable size and the solver's penalty parameters independent of the scene
scale.

Departures from the paper (each deliberate)
-------------------------------------------
1. **The literal cost is unbounded below.** Eq. 12 enforces |N| = 1 only through the
   constraint; with |N|² = 1 + δ (δ > 0) and ``O_j − P`` parallel to N, d_j² = −δ|O_j − P|²,
   which goes to −∞ as the axis point slides away along the axis. A multiplier or penalty
   method can follow that valley for ever, which explains the paper's "GALM alone diverges to
   1e87" (Table 3). The ``normalised`` variant (the default) uses N/|N| in the projection,
   d_j² = |O_j − P|² − (N·(O_j − P))²/|N|², which equals eq. 9 on the constraint surface and
   is never negative. ``normalised=False`` is the paper-literal cost, kept to reproduce
   Table 3.
2. **Handedness and orthonormality.** The paper has no constraint a1 ⊥ a3. When x is turned
   into a transform, a1 and a3 are normalised, the second column is a2 = a3 × a1 (so that
   [a1, a2, a3] is right-handed) and the matrix is projected onto SO(3) by SVD.
3. **Internal length unit** as described under *Units*.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from linelaser_calib.core.errors import DegenerateError, InputError
from linelaser_calib.core.geometry import check_transform, project_to_so3
from linelaser_calib.core.types import FloatArray


@dataclass(frozen=True)
class Cylinder:
    """A cylinder in the base frame.

    Attributes
    ----------
    point : ndarray, shape (3,)
        A point on the axis, m (the one closest to the base origin).
    direction : ndarray, shape (3,)
        Unit axis direction.
    radius : float
        m.
    """

    point: FloatArray
    direction: FloatArray
    radius: float


#: Number of unknowns in the paper's vector x (eq. 10).
N_PARAMS = 15
#: Number of equality constraints (eq. 11).
N_CONSTRAINTS = 3
#: Slices of x: first and third hand-eye rotation columns, translation, axis point, direction.
A1 = slice(0, 3)
A3 = slice(3, 6)
TRANS = slice(6, 9)
POINT = slice(9, 12)
DIRECTION = slice(12, 15)

#: Fewest centres accepted: 10 effective unknowns, 2 equations per centre, plus margin.
MIN_CENTRES = 6
#: Smallest spread of flange orientations (rad) that still determines the hand-eye rotation.
MIN_ORIENTATION_SPREAD_RAD = np.deg2rad(1.0)
#: Floor of |N|² in the normalised cost, to keep N = 0 finite.
_TINY = 1e-300


@dataclass(frozen=True)
class CentreAxisProblem:
    """Data of eq. 12 in an internal length unit.

    Build it with :meth:`from_data`.

    Attributes
    ----------
    centres_xz : ndarray, shape (M, 2)
        Ellipse centres (x_c, z_c) in the sensor frame, in units of ``unit_m``.
    rotations : ndarray, shape (M, 3, 3)
        Flange orientations R_j in the base frame.
    positions : ndarray, shape (M, 3)
        Flange positions p_j in the base frame, in units of ``unit_m``.
    unit_m : float
        Metres per internal length unit.
    normalised : bool
        True for the bounded cost with N/|N| (departure 1), False for the literal eq. 9.
    """

    centres_xz: FloatArray
    rotations: FloatArray
    positions: FloatArray
    unit_m: float
    normalised: bool

    @classmethod
    def from_data(
        cls,
        centres_xz: ArrayLike,
        T_base_flange: ArrayLike,
        *,
        normalised: bool = True,
        unit_m: float | None = None,
    ) -> CentreAxisProblem:
        """Validate SI data and store it in the internal unit.

        Parameters
        ----------
        centres_xz : array-like, shape (M, 2)
            Ellipse centres in the sensor x-z plane, m.
        T_base_flange : array-like, shape (M, 4, 4)
            Flange poses in the base frame (translation in m), one per centre.
        normalised : bool
            Use the bounded cost (default) or the paper-literal one.
        unit_m : float, optional
            Metres per internal unit; default the RMS norm of the centres.

        Raises
        ------
        InputError
            Wrong shapes, NaN/Inf, invalid transforms, too few centres, bad unit.
        DegenerateError
            All flange orientations (nearly) equal: the hand-eye rotation is not observable.
        """
        c = np.asarray(centres_xz, dtype=np.float64)
        T_all = np.asarray(T_base_flange, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] != 2:
            raise InputError(f"centres_xz must have shape (M, 2), got {c.shape}")
        if T_all.shape != (c.shape[0], 4, 4):
            raise InputError(
                f"T_base_flange must have shape ({c.shape[0]}, 4, 4) to match the centres, "
                f"got {T_all.shape}"
            )
        if c.shape[0] < MIN_CENTRES:
            raise InputError(
                f"{c.shape[0]} centres given, at least {MIN_CENTRES} are needed: "
                "scan the cylinder from more flange poses"
            )
        if not np.all(np.isfinite(c)):
            raise InputError("centres_xz contains NaN or Inf: drop the failed ellipse fits")
        for j, T_j in enumerate(T_all):
            try:
                check_transform(T_j, tolerance=1e-4)
            except ValueError as err:
                raise InputError(f"T_base_flange[{j}] is not a rigid transform: {err}") from err
        if unit_m is None:
            unit_m = float(np.sqrt(np.mean(np.sum(c**2, axis=1))))
        if not (np.isfinite(unit_m) and unit_m > 0.0):
            raise InputError(
                f"length unit {unit_m} m is not positive: the centres are all at the sensor "
                "origin, check that they are in metres"
            )
        R = T_all[:, :3, :3]
        spread = np.arccos(np.clip((np.einsum("ij,kij->k", R[0], R) - 1.0) / 2.0, -1.0, 1.0))
        if float(np.max(spread)) < MIN_ORIENTATION_SPREAD_RAD:
            raise DegenerateError(
                "all flange orientations are within "
                f"{np.rad2deg(MIN_ORIENTATION_SPREAD_RAD):.1f} deg of each other: the hand-eye "
                "rotation is not observable; tilt and rotate the flange between scans"
            )
        return cls(
            centres_xz=c / unit_m,
            rotations=np.ascontiguousarray(R),
            positions=T_all[:, :3, 3] / unit_m,
            unit_m=float(unit_m),
            normalised=normalised,
        )

    @property
    def n_centres(self) -> int:
        """Number of centres M."""
        return int(self.centres_xz.shape[0])

    def centres_in_base(self, x: ArrayLike) -> FloatArray:
        """Centres O_j in the base frame (eq. 6), internal units.

        Parameters
        ----------
        x : array-like, shape (15,) or (K, 15)

        Returns
        -------
        ndarray, shape (M, 3) or (K, M, 3)
        """
        X = np.asarray(x, dtype=np.float64)
        Xk = np.atleast_2d(X)
        s = (
            self.centres_xz[None, :, 0, None] * Xk[:, None, A1]
            + self.centres_xz[None, :, 1, None] * Xk[:, None, A3]
            + Xk[:, None, TRANS]
        )
        O_all = np.einsum("mij,kmj->kmi", self.rotations, s) + self.positions[None]
        return np.asarray(O_all[0] if X.ndim == 1 else O_all)

    def squared_distances(self, x: ArrayLike) -> FloatArray:
        """Squared centre-to-axis distances d_j² (eq. 9, or its normalised form), units².

        Parameters
        ----------
        x : array-like, shape (15,) or (K, 15)

        Returns
        -------
        ndarray, shape (M,) or (K, M)
        """
        X = np.asarray(x, dtype=np.float64)
        d2 = self._axis_terms(np.atleast_2d(X))[3]
        return d2[0] if X.ndim == 1 else d2

    def cost(self, x: ArrayLike) -> FloatArray:
        """f(x) = Σ_j d_j² (eq. 12), units²: x (15,) gives shape (), a swarm (K, 15) gives (K,)."""
        return np.asarray(np.sum(self.squared_distances(x), axis=-1))

    def cost_and_gradient(self, x: ArrayLike) -> tuple[float, FloatArray]:
        """f(x) (units²) and its analytic gradient, shape (15,), for one x (15,)."""
        X = np.asarray(x, dtype=np.float64).reshape(1, N_PARAMS)
        W, s, perp, d2 = (a[0] for a in self._axis_terms(X))
        G = 2.0 * perp  # df/dO_j = 2 (W_j − s_j N), (M, 3)
        U = np.einsum("mji,mj->mi", self.rotations, G)  # R_jᵀ df/dO_j
        grad = np.empty(N_PARAMS)
        grad[A1] = self.centres_xz[:, 0] @ U
        grad[A3] = self.centres_xz[:, 1] @ U
        grad[TRANS] = U.sum(axis=0)
        grad[POINT] = -G.sum(axis=0)
        grad[DIRECTION] = -2.0 * (s @ W)
        if self.normalised:
            grad[DIRECTION] += 2.0 * float(s @ s) * X[0, DIRECTION]
        return float(np.sum(d2)), grad

    def distances_m(self, x: ArrayLike) -> FloatArray:
        """Centre-to-axis distances in metres, shape (M,), with the axis direction normalised.

        Use it for residual reports; it does not depend on ``normalised``.
        """
        X = np.asarray(x, dtype=np.float64).reshape(1, N_PARAMS)
        perp = self._axis_terms(X, force_normalised=True)[2]
        return np.asarray(np.linalg.norm(perp[0], axis=1) * self.unit_m)

    def constraints(self, x: ArrayLike) -> FloatArray:
        """h(x) (eq. 11), shape (3,) or (K, 3); see :func:`constraints`."""
        return constraints(x)

    def constraints_jacobian(self, x: ArrayLike) -> FloatArray:
        """Jacobian of h, shape (3, 15); see :func:`constraints_jacobian`."""
        return constraints_jacobian(x)

    def _axis_terms(
        self, X: FloatArray, *, force_normalised: bool = False
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Terms of d_j² for a batch X (K, 15).

        Returns W = O − P (K, M, 3), the projection coefficient s (K, M) (N·W, divided by
        |N|² when normalised), the perpendicular part W − sN (K, M, 3) and d² (K, M).
        d² is evaluated as |W − sN|² (+ s²(1 − |N|²) for the literal cost), which equals
        eq. 9 but does not lose the small distances to cancellation against |W|².
        """
        W = self.centres_in_base(X) - X[:, None, POINT]
        Nv = X[:, DIRECTION]
        s = np.einsum("kmi,ki->km", W, Nv)
        nn = np.sum(Nv**2, axis=1)
        normalised = self.normalised or force_normalised
        if normalised:
            s = s / np.maximum(nn, _TINY)[:, None]
        perp = W - s[:, :, None] * Nv[:, None, :]
        d2 = np.sum(perp**2, axis=2)
        if not normalised:
            d2 = d2 + s**2 * (1.0 - nn)[:, None]
        return W, s, perp, d2


def constraints(x: ArrayLike) -> FloatArray:
    """Unit-norm constraints h(x) = [|a1|² − 1, |a3|² − 1, |N|² − 1] (eq. 11).

    Parameters
    ----------
    x : array-like, shape (15,) or (K, 15)

    Returns
    -------
    ndarray, shape (3,) or (K, 3)
    """
    X = np.asarray(x, dtype=np.float64)
    return np.stack(
        [
            np.sum(X[..., A1] ** 2, axis=-1) - 1.0,
            np.sum(X[..., A3] ** 2, axis=-1) - 1.0,
            np.sum(X[..., DIRECTION] ** 2, axis=-1) - 1.0,
        ],
        axis=-1,
    )


def constraints_jacobian(x: ArrayLike) -> FloatArray:
    """Jacobian dh/dx of :func:`constraints`, shape (3, 15), for one x (15,)."""
    X = np.asarray(x, dtype=np.float64)
    J = np.zeros((N_CONSTRAINTS, N_PARAMS))
    J[0, A1] = 2.0 * X[A1]
    J[1, A3] = 2.0 * X[A3]
    J[2, DIRECTION] = 2.0 * X[DIRECTION]
    return J


def calibration_from_x(x: ArrayLike, unit_m: float = 1.0) -> tuple[FloatArray, Cylinder]:
    """Hand-eye transform and cylinder axis from the paper's 15-vector.

    a1 and a3 are normalised, a2 = a3 × a1 completes a right-handed frame and the rotation
    is projected onto SO(3) by SVD (departure 2). The axis point returned is the one closest
    to the base origin and the direction is unit (its sign is as solved).

    Parameters
    ----------
    x : array-like, shape (15,)
        Lengths (t, P) in units of ``unit_m``.
    unit_m : float
        Metres per unit of x.

    Returns
    -------
    T_flange_sensor : ndarray, shape (4, 4)
        Translation in m.
    cylinder : Cylinder
        Axis in the base frame, m. This model does not estimate the radius: it is NaN and the
        caller sets it (``dataclasses.replace``).

    Raises
    ------
    InputError
        x is not a finite 15-vector.
    DegenerateError
        A zero column or direction, or a1 parallel to a3.
    """
    X = np.asarray(x, dtype=np.float64)
    if X.shape != (N_PARAMS,) or not np.all(np.isfinite(X)):
        raise InputError(f"x must be a finite vector of {N_PARAMS} values, got {X!r}")
    norms = [np.linalg.norm(X[A1]), np.linalg.norm(X[A3]), np.linalg.norm(X[DIRECTION])]
    if min(norms) == 0.0:
        raise DegenerateError(f"x has a zero rotation column or axis direction: {X!r}")
    a1 = X[A1] / norms[0]
    a3 = X[A3] / norms[1]
    a2 = np.cross(a3, a1)
    if np.linalg.norm(a2) < 1e-9:
        raise DegenerateError("the hand-eye columns a1 and a3 are parallel: no rotation fits")
    T_flange_sensor = np.eye(4)
    T_flange_sensor[:3, :3] = project_to_so3(np.column_stack([a1, a2 / np.linalg.norm(a2), a3]))
    T_flange_sensor[:3, 3] = X[TRANS] * unit_m
    direction = X[DIRECTION] / norms[2]
    point = X[POINT] * unit_m
    point = point - float(point @ direction) * direction
    return T_flange_sensor, Cylinder(point=point, direction=direction, radius=float("nan"))


def x_from_calibration(
    T_flange_sensor: ArrayLike, cylinder: Cylinder, unit_m: float = 1.0
) -> FloatArray:
    """The paper's 15-vector (eq. 10) of a hand-eye and a cylinder axis.

    Parameters
    ----------
    T_flange_sensor : array-like, shape (4, 4)
        Translation in m.
    cylinder : Cylinder
        Axis in the base frame, m (radius unused).
    unit_m : float
        Metres per unit of the returned lengths.

    Returns
    -------
    ndarray, shape (15,)
    """
    T_fs = np.asarray(T_flange_sensor, dtype=np.float64)
    direction = np.asarray(cylinder.direction, dtype=np.float64)
    return np.concatenate(
        [
            T_fs[:3, 0],
            T_fs[:3, 2],
            T_fs[:3, 3] / unit_m,
            np.asarray(cylinder.point, dtype=np.float64) / unit_m,
            direction / np.linalg.norm(direction),
        ]
    )


def centre_distances(
    centres_xz: ArrayLike,
    T_base_flange: ArrayLike,
    T_flange_sensor: ArrayLike,
    cylinder: Cylinder,
) -> FloatArray:
    """Distance of each centre, mapped into the base frame (eq. 6), to the cylinder axis.

    Parameters
    ----------
    centres_xz : array-like, shape (M, 2)
        Ellipse centres in the sensor x-z plane, m.
    T_base_flange : array-like, shape (M, 4, 4)
        Flange poses, m.
    T_flange_sensor : array-like, shape (4, 4)
        Hand-eye, m.
    cylinder : Cylinder
        Axis in the base frame, m.

    Returns
    -------
    ndarray, shape (M,)
        Distances, m.
    """
    problem = CentreAxisProblem.from_data(centres_xz, T_base_flange, unit_m=1.0)
    return problem.distances_m(x_from_calibration(T_flange_sensor, cylinder))
