"""Serial robot kinematics: one model for DH tables and URDF chains, FK, IK and Jacobians.

A :class:`KinematicModel` is a fixed base transform, a sequence of elementary motions
(:class:`Element`) and a fixed tip transform::

    T_base_flange(q) = T_base_root · E_1 · E_2 ··· E_K · T_tip_flange

Each element is a rotation about, or a translation along, a unit axis of the frame before
it, by ``value`` (+ ``q[joint]`` for a joint element). The element values are the model's
kinematic parameters (SI: m, rad), named ``<joint>.<what>``; a joint element's value is the
joint's zero offset.

- A standard Denavit-Hartenberg link (as Universal Robots publish them) is
  ``A_i = Rz(θ_i + offset_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)``: four elements named
  ``offset``, ``d``, ``a``, ``alpha``.
- A URDF joint is ``origin(xyz, rpy) · motion(axis)``, with ``R(rpy) = Rz(yaw) Ry(pitch)
  Rx(roll)``: elements ``x``, ``y``, ``z``, ``yaw``, ``pitch``, ``roll`` and, for a revolute
  or prismatic joint, ``offset`` about or along the joint axis.

Presets :data:`UR_DH` hold the nominal DH tables Universal Robots publish for the UR5e and
UR10e. Their chain starts at ``base_link``, which the UR ROS description turns 180° about z
from the DH base frame ``base``, and ends at ``tool0`` (DH frame 6), as the ROS driver's
``/tf`` does.

The parameter Jacobian (:func:`parameter_jacobian`) is analytic: the derivative of the
flange pose with respect to an element's value is that element's unit twist carried into
the base frame. Its joint columns are the robot's geometric joint Jacobian, which the
numerical inverse kinematics (:func:`inverse_kinematics`) uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..geometry import rotvec_from_matrix
from ..pose_track import PoseTrack
from ..types import FloatArray

_UNIT = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


class ElementKind(Enum):
    """What an element does along its axis."""

    ROTATION = "rotation"
    TRANSLATION = "translation"


@dataclass(frozen=True)
class Element:
    """One elementary motion of a chain.

    Attributes
    ----------
    name : str
        Parameter name, ``<joint>.<what>`` (e.g. ``elbow_joint.a``).
    kind : ElementKind
    axis : (3,) floats
        Unit axis in the frame before the element.
    value : float
        Rotation (rad) or translation (m); for a joint element, the joint's zero offset.
    joint : int
        Index into the joint vector of the joint this element moves, or -1 if fixed.
    """

    name: str
    kind: ElementKind
    axis: tuple[float, float, float]
    value: float
    joint: int = -1


@dataclass(frozen=True, eq=False)
class KinematicModel:
    """A serial chain (see the module docstring).

    Attributes
    ----------
    name : str
        ``ur5e``, ``ur10e``, or the URDF robot name.
    joint_names : tuple of str
        Names of the moving joints, in chain order (the order of ``q``).
    elements : tuple of Element
    T_base_root : ndarray, shape (4, 4)
        Fixed transform from the base frame to the chain's first frame.
    T_tip_flange : ndarray, shape (4, 4)
        Fixed transform from the chain's last frame to the flange.
    base_frame, flange_frame : str
    """

    name: str
    joint_names: tuple[str, ...]
    elements: tuple[Element, ...]
    T_base_root: FloatArray
    T_tip_flange: FloatArray
    base_frame: str = "base_link"
    flange_frame: str = "tool0"

    def __post_init__(self) -> None:
        joints = sorted({e.joint for e in self.elements if e.joint >= 0})
        if joints != list(range(len(self.joint_names))):
            raise InputError(
                f"kinematic model {self.name!r}: joint elements {joints} do not cover the "
                f"{len(self.joint_names)} joints {list(self.joint_names)}"
            )
        names = [e.name for e in self.elements]
        if len(set(names)) != len(names):
            raise InputError(f"kinematic model {self.name!r}: repeated parameter names")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the kinematic parameters, one per element."""
        return tuple(e.name for e in self.elements)

    @property
    def parameters(self) -> FloatArray:
        """Parameter values (m or rad), shape (P,)."""
        return np.array([e.value for e in self.elements], dtype=np.float64)

    @property
    def parameter_is_length(self) -> NDArray[np.bool_]:
        """Per parameter, True for a length (m), False for an angle (rad), shape (P,)."""
        return np.array([e.kind is ElementKind.TRANSLATION for e in self.elements])

    def with_parameters(self, values: ArrayLike) -> KinematicModel:
        """The same chain with other parameter values (m, rad), shape (P,)."""
        v = np.asarray(values, dtype=np.float64)
        if v.shape != (len(self.elements),):
            raise ValueError(f"expected {len(self.elements)} parameters, got shape {v.shape}")
        elements = tuple(replace(e, value=float(x)) for e, x in zip(self.elements, v, strict=True))
        return replace(self, elements=elements)


@dataclass(frozen=True, eq=False)
class JointStates:
    """A joint-state stream, as ``sensor_msgs/JointState`` carries it.

    Attributes
    ----------
    names : tuple of str
        Joint names, the column order of ``positions``.
    stamps_ns : ndarray of int64, shape (K,)
    positions : ndarray, shape (K, n)
        Joint positions, rad (revolute) or m (prismatic).
    """

    names: tuple[str, ...]
    stamps_ns: NDArray[np.int64]
    positions: FloatArray


def flange_poses_from_joint_states(
    model: KinematicModel, states: JointStates, *, frame_id: str | None = None
) -> PoseTrack:
    """Flange poses ``T_base_flange`` by forward kinematics of every joint state.

    The states' joints are matched to the model's by name, in any order; joints the model
    does not use (e.g. a gripper) are ignored.

    Raises
    ------
    InputError
        If a joint of the model is missing from the states (both lists are named).
    """
    missing = [name for name in model.joint_names if name not in states.names]
    if missing:
        raise InputError(
            f"the joint states do not name the joints {missing} of the kinematic model "
            f"{model.name!r}; the states name {list(states.names)}, the model needs "
            f"{list(model.joint_names)}. Choose the model of the robot that published them "
            "({setting:kinematics})"
        )
    columns = [states.names.index(name) for name in model.joint_names]
    T = forward_kinematics(model, states.positions[:, columns])
    frame = model.base_frame if frame_id is None else frame_id
    return PoseTrack.from_transforms(states.stamps_ns, T, frame)


def check_joint_positions(model: KinematicModel, q: ArrayLike) -> FloatArray:
    """Joint vectors as an (M, n) float array; raise ``ValueError`` on a bad shape."""
    a = np.asarray(q, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != len(model.joint_names):
        raise ValueError(
            f"joint positions must have shape (M, {len(model.joint_names)}) for "
            f"{model.name!r}, got {np.shape(q)}"
        )
    return a


def _elementary(element: Element, amount: FloatArray) -> FloatArray:
    """Transforms (M, 4, 4) of one element moved by ``amount`` (M,) (m or rad)."""
    T = np.tile(np.eye(4), (len(amount), 1, 1))
    u = np.asarray(element.axis)
    if element.kind is ElementKind.TRANSLATION:
        T[:, :3, 3] = amount[:, None] * u
        return T
    c, s = np.cos(amount), np.sin(amount)
    K = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    T[:, :3, :3] = np.eye(3) + s[:, None, None] * K + (1.0 - c)[:, None, None] * (K @ K)
    return T


def _amounts(model: KinematicModel, q: FloatArray) -> list[FloatArray]:
    return [
        e.value + q[:, e.joint] if e.joint >= 0 else np.full(len(q), e.value)
        for e in model.elements
    ]


def forward_kinematics(model: KinematicModel, q: ArrayLike) -> FloatArray:
    """Flange poses ``T_base_flange`` (M, 4, 4) of joint vectors q (M, n) (rad or m)."""
    joints = check_joint_positions(model, q)
    T = np.tile(model.T_base_root, (len(joints), 1, 1))
    for element, amount in zip(model.elements, _amounts(model, joints), strict=True):
        T = T @ _elementary(element, amount)
    return np.asarray(T @ model.T_tip_flange)


def flange_side_transform(model: KinematicModel) -> FloatArray:
    """The fixed end of the chain, (4, 4): the last joint element at its zero offset (q = 0)
    and every element after it, then ``T_tip_flange``.

    ``FK(q) = P(q) · M(q_last) · flange_side_transform(model)``, where ``M`` is the last
    joint's motion by q_last alone (a rotation about, or translation along, the element's own
    axis commutes with the offset on it) and ``P`` the chain before it. An error in these
    parameters is therefore one constant transform in the flange frame at every pose.
    """
    last = max(i for i, e in enumerate(model.elements) if e.joint >= 0)
    T = np.eye(4)
    for element in model.elements[last:]:
        T = T @ _elementary(element, np.array([element.value]))[0]
    return np.asarray(T @ model.T_tip_flange)


def effective_hand_eye(
    model: KinematicModel, true: KinematicModel, T_flange_sensor: ArrayLike
) -> FloatArray:
    """The hand-eye (4, 4) that flange poses from ``model`` see on an arm whose kinematics are
    ``true``: ``L_model⁻¹ · L_true · T_flange_sensor`` with L the
    :func:`flange_side_transform`.

    The arm's error in the parameters after its last joint's motion (the last link's length,
    twist and zero offset) moves the sensor by one constant transform in the flange frame, the
    same at every pose; scans of any target with those flange poses cannot tell it from a
    different hand-eye. A calibration is right when it finds this hand-eye: with it and the
    model's flange poses, scan points land where the true hand-eye and the true flange poses
    put them, up to the error of the rest of the chain.
    """
    L = np.linalg.inv(flange_side_transform(model)) @ flange_side_transform(true)
    return np.asarray(L @ np.asarray(T_flange_sensor, dtype=np.float64))


def parameter_jacobian(model: KinematicModel, q: ArrayLike) -> FloatArray:
    """Derivative of the flange pose with respect to every kinematic parameter.

    Parameters
    ----------
    model : KinematicModel
    q : array_like, shape (M, n)
        Joint vectors (rad or m).

    Returns
    -------
    ndarray, shape (M, 6, P)
        Column k is the base-frame twist ``(v, ω)`` with
        ``T(p + ε e_k) ≈ exp(ε [v, ω]^) · T(p)``: a base point x of the flange moves by
        ``ω × x + v`` per unit of parameter k (m/m or m/rad; rad/m or rad/rad). Columns of
        joint elements are also the geometric joint Jacobian.
    """
    joints = check_joint_positions(model, q)
    J = np.zeros((len(joints), 6, len(model.elements)))
    T = np.tile(model.T_base_root, (len(joints), 1, 1))
    for k, (element, amount) in enumerate(
        zip(model.elements, _amounts(model, joints), strict=True)
    ):
        T = T @ _elementary(element, amount)
        axis = T[:, :3, :3] @ np.asarray(element.axis)
        if element.kind is ElementKind.TRANSLATION:
            J[:, :3, k] = axis
        else:
            J[:, :3, k] = np.cross(T[:, :3, 3], axis)
            J[:, 3:, k] = axis
    return J


def joint_columns(model: KinematicModel) -> list[int]:
    """For each joint, the index of the parameter (element) that it moves."""
    return [
        next(k for k, e in enumerate(model.elements) if e.joint == j)
        for j in range(len(model.joint_names))
    ]


def pose_twist(T_target: FloatArray, T: FloatArray) -> FloatArray:
    """Base-frame twists (M, 6) ``(v, ω)`` taking poses T (M, 4, 4) to T_target (M, 4, 4).

    First order: ``T_target ≈ exp([v, ω]^) · T``.
    """
    R = T_target[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2)
    v = T_target[:, :3, 3] - np.einsum("mij,mj->mi", R, T[:, :3, 3])
    return np.concatenate([v, rotvec_from_matrix(R).reshape(-1, 3)], axis=1)


@dataclass(frozen=True)
class IKSolution:
    """Outcome of :func:`inverse_kinematics`.

    Attributes
    ----------
    q : ndarray, shape (M, n)
        Joint vectors (rad or m), wrapped to (-π, π] for revolute joints.
    converged : ndarray of bool, shape (M,)
        Position error below ``tolerance_m`` and rotation error below ``tolerance_rad``.
    """

    q: FloatArray
    converged: NDArray[np.bool_]


def inverse_kinematics(
    model: KinematicModel,
    T_base_flange: ArrayLike,
    seeds: ArrayLike,
    *,
    iterations: int = 100,
    damping: float = 1e-3,
    tolerance_m: float = 1e-9,
    tolerance_rad: float = 1e-9,
) -> IKSolution:
    """Numerical inverse kinematics by damped least squares from several starting vectors.

    Parameters
    ----------
    model : KinematicModel
    T_base_flange : array_like, shape (M, 4, 4)
        Wanted flange poses (m).
    seeds : array_like, shape (S, n)
        Starting joint vectors; each pose starts from every seed and keeps the converged
        solution nearest to the first seed.
    iterations : int
    damping : float
        Levenberg damping of the normal equations, relative to the mean diagonal of J^T J
        and shrinking with the remaining error (below 1 m or rad), so that the last steps are
        Gauss-Newton steps.
    tolerance_m, tolerance_rad : float
        Convergence thresholds on the remaining position (m) and rotation (rad) error.

    Returns
    -------
    IKSolution
    """
    targets = np.asarray(T_base_flange, dtype=np.float64).reshape(-1, 4, 4)
    starts = check_joint_positions(model, seeds)
    M, S, n = len(targets), len(starts), len(model.joint_names)
    q = np.repeat(starts[None], M, axis=0).reshape(M * S, n)
    goal = np.repeat(targets, S, axis=0)
    cols = joint_columns(model)
    revolute = np.array([model.elements[c].kind is ElementKind.ROTATION for c in cols])
    for _ in range(iterations):
        err = pose_twist(goal, forward_kinematics(model, q))
        J = parameter_jacobian(model, q)[:, :, cols]
        JtJ = np.einsum("mik,mil->mkl", J, J)
        scale = (1.0 + np.trace(JtJ, axis1=1, axis2=2) / n) * np.minimum(
            1.0, np.linalg.norm(err, axis=1)
        )
        JtJ += damping * scale[:, None, None] * np.eye(n)
        q = q + np.linalg.solve(JtJ, np.einsum("mik,mi->mk", J, err)[..., None])[..., 0]
    q[:, revolute] = np.mod(q[:, revolute] + math.pi, 2.0 * math.pi) - math.pi
    err = pose_twist(goal, forward_kinematics(model, q))
    ok = (np.linalg.norm(err[:, :3], axis=1) <= tolerance_m) & (
        np.linalg.norm(err[:, 3:], axis=1) <= tolerance_rad
    )
    solutions, converged = q.reshape(M, S, n), ok.reshape(M, S)
    distance = np.linalg.norm(solutions - starts[0], axis=2) + np.where(converged, 0.0, np.inf)
    best = np.argmin(distance, axis=1)
    return IKSolution(solutions[np.arange(M), best], converged[np.arange(M), best])


def _rz(angle: float) -> FloatArray:
    T = np.eye(4)
    c, s = math.cos(angle), math.sin(angle)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def dh_model(
    name: str,
    joint_names: tuple[str, ...],
    d: ArrayLike,
    a: ArrayLike,
    alpha: ArrayLike,
    *,
    T_base_root: FloatArray | None = None,
    base_frame: str = "base_link",
    flange_frame: str = "tool0",
) -> KinematicModel:
    """A chain from a standard DH table (zero joint offsets).

    Parameters
    ----------
    name : str
    joint_names : tuple of str, length n
    d, a : array_like, shape (n,)
        Link offsets along z and lengths along x, m.
    alpha : array_like, shape (n,)
        Link twists about x, rad.
    T_base_root : ndarray (4, 4), optional
        Base frame to DH frame 0 (default identity).
    """
    d_, a_, alpha_ = (np.asarray(v, dtype=np.float64) for v in (d, a, alpha))
    elements: list[Element] = []
    for j, joint in enumerate(joint_names):
        elements += [
            Element(f"{joint}.offset", ElementKind.ROTATION, _UNIT["z"], 0.0, j),
            Element(f"{joint}.d", ElementKind.TRANSLATION, _UNIT["z"], float(d_[j])),
            Element(f"{joint}.a", ElementKind.TRANSLATION, _UNIT["x"], float(a_[j])),
            Element(f"{joint}.alpha", ElementKind.ROTATION, _UNIT["x"], float(alpha_[j])),
        ]
    return KinematicModel(
        name,
        tuple(joint_names),
        tuple(elements),
        np.eye(4) if T_base_root is None else np.asarray(T_base_root, dtype=np.float64),
        np.eye(4),
        base_frame,
        flange_frame,
    )


@dataclass(frozen=True)
class JointSpec:
    """One joint of a URDF chain, as parsed from the file (SI units).

    Attributes
    ----------
    name : str
    kind : str
        ``revolute``, ``continuous``, ``prismatic`` or ``fixed``.
    xyz, rpy : (3,) floats
        The joint origin: translation (m) and roll, pitch, yaw (rad).
    axis : (3,) floats
        Joint axis in the joint frame (normalised here).
    """

    name: str
    kind: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)


#: Joint kinds of a URDF chain that this model handles.
URDF_JOINT_KINDS = ("revolute", "continuous", "prismatic", "fixed")


def urdf_model(
    name: str,
    chain: list[JointSpec],
    *,
    base_frame: str,
    flange_frame: str,
) -> KinematicModel:
    """A chain from URDF joints listed from the base link to the flange link."""
    elements: list[Element] = []
    moving: list[str] = []
    for spec in chain:
        if spec.kind not in URDF_JOINT_KINDS:
            raise InputError(
                f"joint {spec.name!r} has type {spec.kind!r}; a serial chain supports "
                f"{', '.join(URDF_JOINT_KINDS)}"
            )
        x, y, z = spec.xyz
        roll, pitch, yaw = spec.rpy
        elements += [
            Element(f"{spec.name}.x", ElementKind.TRANSLATION, _UNIT["x"], x),
            Element(f"{spec.name}.y", ElementKind.TRANSLATION, _UNIT["y"], y),
            Element(f"{spec.name}.z", ElementKind.TRANSLATION, _UNIT["z"], z),
            Element(f"{spec.name}.yaw", ElementKind.ROTATION, _UNIT["z"], yaw),
            Element(f"{spec.name}.pitch", ElementKind.ROTATION, _UNIT["y"], pitch),
            Element(f"{spec.name}.roll", ElementKind.ROTATION, _UNIT["x"], roll),
        ]
        if spec.kind == "fixed":
            continue
        axis = np.asarray(spec.axis, dtype=np.float64)
        norm = float(np.linalg.norm(axis))
        if not norm > 1e-9:
            raise InputError(f"joint {spec.name!r} has a zero axis")
        unit = axis / norm
        kind = ElementKind.TRANSLATION if spec.kind == "prismatic" else ElementKind.ROTATION
        elements.append(
            Element(
                f"{spec.name}.offset",
                kind,
                (float(unit[0]), float(unit[1]), float(unit[2])),
                0.0,
                len(moving),
            )
        )
        moving.append(spec.name)
    if not moving:
        raise InputError(f"the chain {base_frame} -> {flange_frame} has no moving joint")
    return KinematicModel(
        name, tuple(moving), tuple(elements), np.eye(4), np.eye(4), base_frame, flange_frame
    )


#: Joint names of Universal Robots arms, as their ROS driver publishes them.
UR_JOINT_NAMES = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)

_HALF_PI = math.pi / 2.0

#: Nominal DH tables published by Universal Robots: (d, a, alpha), m and rad.
UR_DH: dict[str, tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]] = {
    "ur5e": (
        (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996),
        (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0),
        (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0),
    ),
    "ur10e": (
        (0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655),
        (0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0),
        (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0),
    ),
}


def model_from_preset(name: str) -> KinematicModel:
    """The nominal model of a preset in :data:`UR_DH`, from ``base_link`` to ``tool0``.

    Raises
    ------
    InputError
        For an unknown preset.
    """
    if name not in UR_DH:
        raise InputError(
            f"unknown kinematic preset {name!r}; choose one of {sorted(UR_DH)} or give a URDF file"
        )
    d, a, alpha = UR_DH[name]
    return dh_model(name, UR_JOINT_NAMES, d, a, alpha, T_base_root=_rz(math.pi))


@dataclass(frozen=True)
class KinematicCorrections:
    """Corrections to a model's nominal kinematic parameters (the result's ``kinematics``).

    Attributes
    ----------
    model : str
        The model they apply to: a preset name (``ur5e``) or a URDF file.
    corrections : dict of str to float
        Parameter name (``<joint>.<what>``, see :class:`KinematicModel`) to the value added
        to the nominal one: m for lengths, rad for angles. Parameters not listed keep their
        nominal value.
    kept_nominal : tuple of str
        Parameters a calibration could not determine and left nominal (for the record).
    """

    model: str
    corrections: dict[str, float]
    kept_nominal: tuple[str, ...] = ()

    def apply(self, model: KinematicModel) -> KinematicModel:
        """``model`` with the corrections added to its parameters.

        Raises
        ------
        InputError
            If a corrected parameter is not one of the model's.
        """
        names = model.parameter_names
        unknown = sorted(set(self.corrections) - set(names))
        if unknown:
            raise InputError(
                f"the kinematic corrections name parameters {unknown} that the model "
                f"{model.name!r} does not have; its parameters are {list(names)}"
            )
        delta = np.array([self.corrections.get(name, 0.0) for name in names])
        return model.with_parameters(model.parameters + delta)
