"""The cylinder's refinement problem in the shared solver's block form: residuals, Jacobians.

Model
-----
Sample j has profile points p_jk (sensor frame, m) and a reported flange pose T_j =
``T_base_flange[j]``. The robot's pose error is a per-sample nuisance δ_j = (ω_j, τ_j): a
rotation vector ω_j (rad) and a translation τ_j (m), both in the **flange frame** (right
perturbation), so that the true flange pose is

    T_j · D(δ_j),   D(δ) = [[Exp(ω), τ], [0, 1]],

i.e. the flange's true orientation is R_j·Exp(ω_j) (a rotation about the flange origin) and
its true position t_j + R_j·τ_j. For an isotropic robot error this is the same distribution as
an error stated in the base frame, and it keeps rotation and translation errors decoupled
(a base-frame rotation would swing the flange about the robot base). A point maps into the
base frame as

    x_jk = T_j · D(δ_j) · T_flange_sensor · S⁻¹ · p_jk,   S = diag(1 + s, 1, 1 + s_z),

where s is the sensor's along-line scale error (dimensionless; 0 unless estimated): a
profiler that reports x as (1 + s) times the true value (s = 0.005 reads 0.5 % long)
stretches each arc across the line and shifts its centre by s times its along-line
position. s_z is its depth scale error about the sensor origin (0 unless estimated): it
moves every point by s_z times its depth, about s_z · 0.1 m at a typical range, which the
robot's motions tell from a shift of the hand-eye by the arcs' spread in depth.

The cylinder has an axis point c, a unit direction d and a radius R. The residuals are

- per point: (‖(I − d dᵀ)(x_jk − c)‖ − R) / σ_s, under a robust loss (Huber or soft-L1 with
  a scale of ``loss_scale`` σ) against spikes;
- per sample: the Gaussian priors ω_j / σ_r and τ_j / σ_t (no robust loss).

Minimising their sum (``½ Σ loss + ½ Σ prior²``) is the joint maximum a-posteriori estimate of
the hand-eye, axis, radius and pose corrections; in the linearised (Gaussian) model the
hand-eye part equals the maximum-likelihood estimate with the corrections integrated out.

Scales and the noise's units
----------------------------
With a scale estimated, the point residuals are kept in the sensor's own (measured) units:
each is multiplied by g = 1 + a s + b s_z, a and b the shares of its noise that the sensor
reports along the line (x) and in depth (z) (:meth:`CylinderProblem.with_scale_shares`).
A scale maps the measured points, noise included, to true ones (z / (1 + s_z)), so in true
units every residual shrinks by 1 / (1 + s_z) as s_z grows, and a least-squares fit buys
that shrink with a stretch: the scale's regressor is the measured depth, noise and all
(errors in variables), and the normal equations' score at the truth is off by the
residuals' χ² (about one per point), so s_z reads high by about (points) × σ_z²,
σ_z its own 1σ. The measured-unit residual (the likelihood of the measured points) has no
such shrink. On ``cylinder_gocator`` with its z scale true (12 µm smooth shape error,
about 18,000 points, σ_z 0.04 %) the depth scale read +0.20 to +0.35 % over 9 seeds
(5-8σ) and moved the hand-eye 0.2-0.45 mm along the sensor's depth; so weighed it reads
-0.11 to +0.01 %. The smooth shape error only widens σ_z (0.015 % without it), which is
why it seemed to cause the bias. The x scale reads high in the same way by its share of
the white noise.
That correction is first order: where a large smooth shape error sets the x scale's
variance it is no better than its own size, so its move counts in the 1σ
(:func:`errors_in_variables_move`).

Parametrisation and solver
--------------------------
Every iteration linearises around the current estimate in local coordinates:

- hand-eye: ``R = R̂ · Exp(θ)`` (θ about the **sensor** axes), ``t = t̂ + ρ`` (ρ in the
  **flange** frame);
- axis: ``d = normalise(d̂ + a₁u + a₂v)``, ``c = ĉ + b₁u + b₂v`` with (u, v) ⟂ d̂ (4 numbers,
  no singularity; the point is kept nearest to the data's centroid, which only slides it
  along the axis);
- radius: R = R̂ + r (only when estimated);
- along-line scale: s = ŝ + σ (only when estimated; ``estimate_scale``);
- depth scale: s_z = ŝ_z + σ_z (only when estimated; ``estimate_depth_scale``);
- corrections: ω_j, τ_j additively (exact right Jacobian of Exp).

The Jacobian is analytic and block-sparse: a point depends on the G = 10 to 13 global
numbers and on its sample's 6. The shared block solver
(:mod:`linelaser_calib.core.solver`: Levenberg–Marquardt with Marquardt scaling, Nielsen's
damping update and iteratively re-weighted robust weights) solves the normal equations by a
Schur complement: each sample's 6×6 block is inverted on its own and eliminated, leaving a
G×G system. Cost and time grow linearly with the number of samples.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import DegenerateError, InputError
from ...geometry import FloatArray, check_transform, exp_so3, orthonormal_basis, right_jacobian_so3
from ...profile.along_line import measured_to_true
from ...profile.noise import Whitening
from ...solver import N_HAND_EYE, BlockNormal, Linearisation, Residuals
from ...types import StoredArray
from .config import RefineConfig
from .model import Cylinder

#: Axis parameters (a, b) in the global block, after the hand-eye's 6.
N_AXIS = 4
#: Points per chunk of samples :meth:`CylinderProblem.linearise` builds its Jacobians from:
#: its per-point intermediates (about twenty arrays of 3 to 12 columns) stay a few MB each
#: (about 15 MB together at 2**15 points, a solve's largest transient; 2**13 a quarter of
#: that, the same CPU time within the machine's noise on ur_scancontrol at 1,600 poses).
CHUNK_POINTS = 1 << 13


# --------------------------------------------------------------------------------------
# The problem in the shared solver's block form


@dataclass(frozen=True)
class CylinderState:
    """Current estimate (absolute values, not increments).

    Attributes
    ----------
    R_fs : ndarray, shape (3, 3)
    t_fs : ndarray, shape (3,)
        Hand-eye, m.
    point : ndarray, shape (3,)
        On the axis, base frame, m.
    direction : ndarray, shape (3,)
        Unit axis direction.
    radius : float
        m.
    omega, tau : ndarray, shape (M, 3)
        Pose corrections, rad and m, flange frame.
    scale : float
        The sensor's along-line scale error s (dimensionless).
    depth_scale : float
        The sensor's depth scale error s_z about its origin (dimensionless).
    """

    R_fs: FloatArray
    t_fs: FloatArray
    point: FloatArray
    direction: FloatArray
    radius: float
    omega: FloatArray
    tau: FloatArray
    scale: float = 0.0
    depth_scale: float = 0.0


class _Geometry(NamedTuple):
    """Per-point intermediate quantities at one state."""

    p: FloatArray  # (M, K, 3) sensor point with the scale errors removed, S⁻¹ p
    y: FloatArray  # (M, K, 3) point in the nominal flange frame, R_fs S⁻¹ p + t_fs
    RE: FloatArray  # (M, 3, 3) R_bf·Exp(ω) per sample
    distance: FloatArray  # (M, K) distance to the axis, m
    normal: FloatArray  # (M, K, 3) unit radial direction in the base frame
    along: FloatArray  # (M, K) d · (x − c)


@dataclass(frozen=True)
class CylinderProblem:
    """Validated, subsampled data in a padded (samples × points) layout; a
    :class:`~linelaser_calib.core.solver.BlockProblem`.

    Sample j's points fill ``points[j, :counts[j]]``; the rest repeat its first point and are
    masked out (residual and Jacobian rows zero), so that every per-point operation is a
    batched array operation without gathers. Global step: θ (3), ρ (3), a (2), b (2) and,
    when estimated, the radius, the along-line scale and the depth scale (see the module
    docstring).
    With ``centroid`` set, a retraction slides the axis point along the axis to the point
    nearest it (same cylinder).
    """

    points: StoredArray  # (M, K, 3) sensor frame, m; float32 where the input was exactly so
    mask: NDArray[np.bool_]  # (M, K) True for a real point, False for padding (1 byte a point)
    counts: np.ndarray  # (M,) real points per sample
    R_bf: FloatArray  # (M, 3, 3)
    t_bf: FloatArray  # (M, 3)
    estimate_radius: bool
    config: RefineConfig
    centroid: FloatArray | None = None
    estimate_scale: bool = False
    estimate_depth_scale: bool = False
    whitening: Whitening | None = None  # per-sample W with W C Wᵀ = I, or None
    scale_shares: NDArray[np.float32] | None = None  # (M, K, 2) a, b of g = 1 + a s + b s_z

    @property
    def n_samples(self) -> int:
        return int(self.R_bf.shape[0])

    @property
    def n_measurements(self) -> int:
        """Real points (padding excluded): a :class:`~...solver.CountedProblem`."""
        return int(self.counts.sum())

    @property
    def x_m(self) -> FloatArray:
        """Each point's place along the line (sensor x), (M, K), m."""
        return np.asarray(self.points[..., 0], dtype=np.float64)

    def take(self, rows: np.ndarray) -> CylinderProblem:
        """The problem of the samples ``rows`` (indices into the sample axis), m as before;
        every sample in order shares this problem's arrays (no copy: ``--scale auto``'s held
        solve and the plain model re-solve the whole solved problem)."""
        index = np.asarray(rows, dtype=np.intp)
        if np.array_equal(index, np.arange(self.n_samples)):
            return self
        return replace(
            self,
            points=self.points[rows],
            mask=self.mask[rows],
            counts=self.counts[rows],
            R_bf=self.R_bf[rows],
            t_bf=self.t_bf[rows],
            whitening=None if self.whitening is None else self.whitening.take(rows),
            scale_shares=None if self.scale_shares is None else self.scale_shares[rows],
        )

    @property
    def n_global(self) -> int:
        extra = (self.estimate_radius, self.estimate_scale, self.estimate_depth_scale)
        return N_HAND_EYE + N_AXIS + sum(extra)

    @property
    def radius_index(self) -> int | None:
        """Position of the radius in the global step, when estimated."""
        return N_HAND_EYE + N_AXIS if self.estimate_radius else None

    @property
    def scale_index(self) -> int | None:
        """Position of the along-line scale in the global step, when estimated."""
        return N_HAND_EYE + N_AXIS + int(self.estimate_radius) if self.estimate_scale else None

    @property
    def depth_scale_index(self) -> int | None:
        """Position of the depth scale in the global step, when estimated."""
        return self.n_global - 1 if self.estimate_depth_scale else None

    @property
    def step_scale(self) -> FloatArray:
        """Rotations and the scales times the lever, lengths as they are."""
        scale = np.ones(self.n_global)
        scale[:3] = lever = lever_arm_m(self)
        for index in (self.scale_index, self.depth_scale_index):
            if index is not None:
                scale[index] = lever
        return scale

    def with_flange_poses(self, T_base_flange: FloatArray) -> CylinderProblem:
        """The same problem at other flange poses (M, 4, 4)."""
        return replace(
            self,
            R_bf=np.ascontiguousarray(T_base_flange[:, :3, :3]),
            t_bf=np.ascontiguousarray(T_base_flange[:, :3, 3]),
        )

    def pose_corrections(self, state: CylinderState) -> FloatArray:
        """``[ω (rad), τ (m)]`` (M, 6) of every sample."""
        return np.hstack([state.omega, state.tau])

    def _prior_sqrt_information(self) -> FloatArray:
        cfg = self.config
        return np.array([1.0 / cfg.robot_sigma_r_rad] * 3 + [1.0 / cfg.robot_sigma_t_m] * 3)

    def residuals(self, state: CylinderState) -> Residuals:
        """Normalised point residuals (M, K), zero on padding, whitened when
        :attr:`whitening` is set, and pose priors (M, 6)."""
        e = self._per_point(state, lambda part, at: part._point_residuals(at, _geometry(part, at)))
        return Residuals(e, self._pose_prior(state))

    def point_residuals(self, state: CylinderState) -> FloatArray:
        """Point-to-surface residuals (M, K) in units of σ_s, zero on padding, never
        whitened."""
        unit = self.config.sensor_sigma_m
        return self._per_point(
            state,
            lambda part, at: (_geometry(part, at).distance - at.radius) * (part.mask / unit),
        )

    def _chunks(
        self, state: CylinderState
    ) -> Iterator[tuple[slice, CylinderProblem, CylinderState]]:
        """Consecutive chunks of samples (:data:`CHUNK_POINTS` points): their rows, their
        problem and the state with their own pose corrections."""
        M, K = self.mask.shape
        step = max(1, CHUNK_POINTS // K)
        for start in range(0, M, step):
            rows = slice(start, min(start + step, M))
            index = np.arange(rows.start, rows.stop)
            yield (
                rows,
                self.take(index),
                replace(state, omega=state.omega[rows], tau=state.tau[rows]),
            )

    def _per_point(
        self,
        state: CylinderState,
        value: Callable[[CylinderProblem, CylinderState], FloatArray],
    ) -> FloatArray:
        """``value(chunk problem, chunk state)`` (m, K) of every chunk, joined (M, K): the
        per-point intermediates never span the whole recording."""
        out = np.empty(self.mask.shape)
        for rows, part, at in self._chunks(state):
            out[rows] = value(part, at)
        return out

    def _point_residuals(self, state: CylinderState, geo: _Geometry) -> FloatArray:
        e = (geo.distance - state.radius) * (self.mask / self.config.sensor_sigma_m)
        if self.scale_shares is not None:
            e = e * self._stretch(state)
        return e if self.whitening is None else self.whitening.apply(e)

    def _stretch(self, state: CylinderState) -> FloatArray:
        """g = 1 + a s + b s_z per point (M, K): a true-unit residual times g is in the
        sensor's measured units (module docstring, "Scales and the noise's units")."""
        assert self.scale_shares is not None
        a, b = self.scale_shares[..., 0], self.scale_shares[..., 1]
        # The shares are held as float32; the stretch is formed in float64.
        return np.asarray(1.0 + a * np.float64(state.scale) + b * np.float64(state.depth_scale))

    def with_scale_shares(self, state: CylinderState) -> CylinderProblem:
        """The problem with its residuals kept in measured units (:attr:`scale_shares`) when
        it estimates a scale; unchanged otherwise.

        The shares follow the noise model the points are weighed by: white noise alike in
        every direction of the laser plane (the learned line noise's white part, or every
        point's noise without one) and a depth noise and smooth error in depth. Of a point's
        white noise the along-line part is n_x² / (n_x² + n_z²) (n the surface normal in the
        sensor frame at ``state``), and the weighed fit counts it by the point's white share
        of its weight, w² (C⁻¹)_ii (1 without a whitening); a = that product, and b = 1 − a
        is the depth part, the depth noise's and the smooth error's included. Then Σ a and
        Σ b are the expectations of the χ² parts the two scales' regressors carry
        (tr(C⁻¹ C_x) and tr(C⁻¹ C_z)), which the g term of their Jacobian cancels.
        """
        if not (self.estimate_scale or self.estimate_depth_scale):
            return self
        # In place: a recording's (M, K) temporaries are few (this runs beside its points).
        a = self._per_point(state, lambda part, at: _sensor_normals(part, at)[..., 0]) ** 2
        total = self.depth_cosines(state)
        np.square(total, out=total)
        total += a
        a /= np.maximum(total, 1e-300, out=total)
        del total
        if self.whitening is not None:
            a *= self.whitening.white_share()
        a *= self.mask
        # Shares lie in [0, 1]: float32 keeps them to 6e-8, and halves the (M, K, 2) array.
        shares = np.stack([a, self.mask - a], axis=-1, dtype=np.float32)
        return replace(self, scale_shares=shares)

    def _pose_prior(self, state: CylinderState) -> FloatArray:
        cfg = self.config
        return np.hstack([state.omega / cfg.robot_sigma_r_rad, state.tau / cfg.robot_sigma_t_m])

    def linearise(self, state: CylinderState) -> Linearisation:
        """Residuals and their analytic Jacobians.

        ``J_global`` (M, K, G) has the columns θ (3), ρ (3), a (2), b (2) and, when
        estimated, the radius and the along-line scale; ``J_local`` (M, K, 6) the columns
        ω (3), τ (3) of the point's own sample; both zero on padding. Built from
        :meth:`linearise_chunks`.
        """
        chunks = list(self.linearise_chunks(state))
        return Linearisation(
            residuals=Residuals(
                np.concatenate([c.residuals.points for c in chunks]), self._pose_prior(state)
            ),
            J_global=np.concatenate([c.J_global for c in chunks]),
            J_local=np.concatenate([c.J_local for c in chunks]),
            pose_prior_sqrt_information=self._prior_sqrt_information(),
        )

    def linearise_chunks(self, state: CylinderState) -> Iterator[Linearisation]:
        """:meth:`linearise` a chunk of samples (:data:`CHUNK_POINTS` points) at a time, in
        order: the solver sums its normal equations over them
        (:class:`~linelaser_calib.core.solver.ChunkedProblem`), so neither the Jacobians
        nor the per-point intermediates ever span the whole recording."""
        sqrt_information = self._prior_sqrt_information()
        for _, part, at in self._chunks(state):
            # Built in a call: this generator keeps no chunk's Jacobians while the next's
            # are built.
            yield part._linearisation(at, sqrt_information)

    def _linearisation(self, state: CylinderState, sqrt_information: FloatArray) -> Linearisation:
        """:meth:`linearise` of all samples at once (a chunk's)."""
        e, J_global, J_local = self._jacobians(state)
        return Linearisation(
            residuals=Residuals(e, self._pose_prior(state)),
            J_global=J_global,
            J_local=J_local,
            pose_prior_sqrt_information=sqrt_information,
        )

    def _jacobians(self, state: CylinderState) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Point residuals (M, K) and their Jacobians (M, K, G) and (M, K, 6) of all samples
        at once (see :meth:`linearise`). Each column block is written into the Jacobians in
        place (no list of blocks joined), and a product with one 3-vector basis is taken over
        all points at once (a broadcast (M, K, 3) @ (3, n) product loops over the samples)."""
        geo = _geometry(self, state)
        M, K = self.mask.shape
        unit = self.mask / self.config.sensor_sigma_m  # (M, K): 1/σ on points, 0 on padding
        n_base = geo.normal * unit[..., None]
        n_flange = n_base @ geo.RE  # rows Exp(ω)ᵀ R_bfᵀ n: d r / d ρ
        n_sensor = n_flange @ state.R_fs  # rows R_fsᵀ n_flange
        u, v = orthonormal_basis(state.direction)
        n_uv = (n_base.reshape(-1, 3) @ np.column_stack([u, v])).reshape(M, K, 2)
        J_global = np.empty((M, K, self.n_global))
        _cross(geo.p, n_sensor, J_global[..., 0:3])
        J_global[..., 3:6] = n_flange
        np.multiply(n_uv, -geo.along[..., None], out=J_global[..., 6:8])
        np.negative(n_uv, out=J_global[..., 8:10])
        if self.radius_index is not None:
            np.negative(unit, out=J_global[..., self.radius_index])
        if self.scale_index is not None:
            # d (x / (1 + s)) / d s = −x / (1 + s)² = −(x / (1 + s)) / (1 + s)
            J_global[..., self.scale_index] = (
                -n_sensor[..., 0] * geo.p[..., 0] / (1.0 + state.scale)
            )
        if self.depth_scale_index is not None:
            J_global[..., self.depth_scale_index] = (
                -n_sensor[..., 2] * geo.p[..., 2] / (1.0 + state.depth_scale)
            )
        J_local = np.empty((M, K, 6))
        J_local[..., :3] = _cross(geo.y, n_flange) @ right_jacobian_so3(state.omega)
        np.matmul(n_base, self.R_bf, out=J_local[..., 3:])  # rows R_bfᵀ n: d r / d τ
        if self.scale_shares is not None:
            # d (g e) = g de + e dg, dg / ds = a, dg / ds_z = b (e the true-unit residual)
            g = self._stretch(state)[..., None]
            J_global *= g
            J_local *= g
            e = (geo.distance - state.radius) * unit
            for index, share in ((self.scale_index, 0), (self.depth_scale_index, 1)):
                if index is not None:
                    J_global[..., index] += e * self.scale_shares[..., share]
        if self.whitening is not None:
            J_global = self.whitening.apply(J_global)
            J_local = self.whitening.apply(J_local)
        return self._point_residuals(state, geo), J_global, J_local

    def depth_cosines(self, state: CylinderState) -> FloatArray:
        """|cosine| (M, K) between each point's surface normal and the sensor's depth axis."""
        return self._per_point(state, lambda part, at: np.abs(_sensor_normals(part, at)[..., 2]))

    def unwhitened_local_jacobian(self, state: CylinderState) -> FloatArray:
        """d point residual / d (ω, τ) of each point's sample (M, K, 6), m per unit, never
        whitened: the directions a sample's own pose correction fits away."""
        plain = replace(self, whitening=None)
        jacobian = np.concatenate([c.J_local for c in plain.linearise_chunks(state)])
        return np.asarray(jacobian * self.config.sensor_sigma_m)

    def retract(
        self, state: CylinderState, step_global: FloatArray, step_local: FloatArray
    ) -> CylinderState:
        """Apply increments in the local coordinates of :meth:`linearise`."""
        u, v = orthonormal_basis(state.direction)
        direction = state.direction + step_global[6] * u + step_global[7] * v
        r, s, z = self.radius_index, self.scale_index, self.depth_scale_index
        moved = CylinderState(
            R_fs=state.R_fs @ exp_so3(step_global[None, :3])[0],
            t_fs=state.t_fs + step_global[3:6],
            point=state.point + step_global[8] * u + step_global[9] * v,
            direction=direction / np.linalg.norm(direction),
            radius=state.radius + (0.0 if r is None else float(step_global[r])),
            omega=state.omega + step_local[:, :3],
            tau=state.tau + step_local[:, 3:],
            scale=state.scale + (0.0 if s is None else float(step_global[s])),
            depth_scale=state.depth_scale + (0.0 if z is None else float(step_global[z])),
        )
        return moved if self.centroid is None else recentred(moved, self.centroid)


def _sample_transforms(
    problem: CylinderProblem, state: CylinderState
) -> tuple[FloatArray, FloatArray]:
    """Per-sample rotation R_bf·Exp(ω) (M, 3, 3) and the base position of the flange-frame
    origin after correction, t_bf + R_bf·τ (M, 3)."""
    RE = problem.R_bf @ exp_so3(state.omega)
    offset = problem.t_bf + np.einsum("mij,mj->mi", problem.R_bf, state.tau)
    return RE, offset


def _geometry(problem: CylinderProblem, state: CylinderState) -> _Geometry:
    """Base-frame points and their relation to the axis."""
    RE, offset = _sample_transforms(problem, state)
    p = measured_to_true(problem.points, state.scale, state.depth_scale)
    # One product over all points (a broadcast (M, K, 3) @ (3, 3) loops over the samples).
    y = (p.reshape(-1, 3) @ state.R_fs.T + state.t_fs).reshape(p.shape)
    radial = y @ RE.transpose(0, 2, 1)
    radial += (offset - state.point)[:, None, :]  # w, the point relative to the axis point
    along = radial @ state.direction
    radial -= along[..., None] * state.direction
    distance = np.sqrt(np.einsum("mki,mki->mk", radial, radial))
    normal = np.divide(radial, np.maximum(distance, 1e-300)[..., None], out=radial)
    return _Geometry(p, y, RE, distance, normal, along)


def _sensor_normals(problem: CylinderProblem, state: CylinderState) -> FloatArray:
    """Each point's unit surface normal in the sensor frame (M, K, 3)."""
    geo = _geometry(problem, state)
    return np.asarray(geo.normal @ geo.RE @ state.R_fs)


def _cross(a: FloatArray, b: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """Cross products of (..., 3) arrays (cheaper than numpy.cross on small last axes), into
    ``out`` where given."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def errors_in_variables_move(problem: CylinderProblem, normal: BlockNormal) -> FloatArray:
    """How far the along-line scale's errors-in-variables correction moves the solution
    (G,): the global step that the residuals' along-line shares (Σ a, :meth:`CylinderProblem.
    with_scale_shares`) add to the normal equations at a solution, through
    the inverse Schur information. Zero without an estimated along-line scale.

    The shares take away the first-order bias of a scale read on noisy points (the
    expected χ² its regressor carries, module docstring), a move of
    about the points' count times the scale's variance. Where a learned smooth shape error
    sets that variance, the correction is no better than its own size: on
    ``cylinder_scancontrol`` with the field's 42 µm smooth error over 4 mm (radius free,
    seeds 0-3) the along-line reading moves 0.4-1.0 % with the shares and lands 0.3-0.75 %
    short of the truth (4-8 of its 1σ), 0.1-0.9 % long without them; with the white noise
    made 0.5 µm it still moves 0.3-1.0 % and lands 0.24-0.65 % short, against 0.04-0.32 %
    long without. So the move counts in the 1σ (:func:`.refine.summarise`), a rank-one term that
    carries the hand-eye along with the scale; where the points' own noise sets the
    variance it is a small share of the 1σ (white-noise profiles, the committed bags).
    The depth scale's share is not counted: with the radius free its reading is a rival
    model of the same stretch (:func:`.scales.with_depth_reading`), whose move is counted
    there.
    """
    moves = np.zeros(problem.n_global)
    index = problem.scale_index
    if problem.scale_shares is None or index is None:
        return moves
    shares = float(problem.scale_shares[..., 0].sum(dtype=np.float64))
    return np.asarray(np.linalg.inv(normal.schur_information())[:, index] * shares)


def data_centroid(problem: CylinderProblem, state: CylinderState) -> FloatArray:
    """Mean of the profiles' centroids in the base frame (3,), m."""
    RE, offset = _sample_transforms(problem, state)
    real = np.multiply(problem.points, problem.mask[..., None], dtype=np.float64)
    means = np.sum(real, axis=1) / problem.counts[:, None]
    y = measured_to_true(means, state.scale, state.depth_scale) @ state.R_fs.T + state.t_fs
    return np.asarray(np.mean(np.einsum("mij,mj->mi", RE, y) + offset, axis=0))


def recentred(state: CylinderState, centroid: FloatArray) -> CylinderState:
    """Slide the axis point along the axis to the point nearest ``centroid`` (same cylinder)."""
    point = state.point + float((centroid - state.point) @ state.direction) * state.direction
    return replace(state, point=point)


# --------------------------------------------------------------------------------------
# Input handling


def _subsample(points: FloatArray, limit: int) -> FloatArray:
    """At most ``limit`` points (0: all), evenly spaced along the profile order."""
    if limit == 0 or len(points) <= limit:
        return points
    return np.asarray(points[np.round(np.linspace(0, len(points) - 1, limit)).astype(int)])


def build_problem(
    samples_points: Sequence[StoredArray],
    T_base_flange: ArrayLike,
    config: RefineConfig,
    estimate_radius: bool,
) -> CylinderProblem:
    """Validate the input (InputError/DegenerateError with advice) and stack it.

    Parameters are those of :func:`.refine.refine`; ``estimate_radius`` adds the radius to the
    global parameters, ``config.estimate_scale`` the along-line scale and
    ``config.estimate_depth_scale`` the depth scale.
    """
    T_all = np.asarray(T_base_flange, dtype=np.float64)
    M = len(samples_points)
    if T_all.shape != (M, 4, 4):
        raise InputError(
            f"T_base_flange must have shape ({M}, 4, 4), one pose per profile, got {T_all.shape}"
        )
    if config.min_samples > M:
        raise DegenerateError(
            f"{M} samples given, but the refinement needs at least {config.min_samples}: "
            "scan the cylinder from more flange poses (20-50 diverse poses are typical)"
        )
    for j, T in enumerate(T_all):
        try:
            check_transform(T, tolerance=1e-4)
        except ValueError as exc:
            raise InputError(f"T_base_flange[{j}] is not a rigid transform: {exc}") from exc
    # Points held as float32 where they all are (stored_points): the same numbers, half the
    # memory of the largest arrays a refinement holds; every use converts a chunk at a time.
    # Each profile is checked and copied into the padded array on its own: no float64 copy
    # of the whole recording.
    narrow = all(np.asarray(p).dtype == np.float32 for p in samples_points)
    for j, p in enumerate(samples_points):
        shape = np.shape(p)
        if len(shape) != 2 or shape[1] != 3:
            raise InputError(f"profile {j} must be an (N, 3) array of points, got shape {shape}")
        if shape[0] < config.min_points_per_profile:
            raise InputError(
                f"profile {j} has {shape[0]} points, fewer than {config.min_points_per_profile}: "
                "drop it or check the profile cleaning"
            )
    limit = config.max_points_per_profile
    counts = np.array([len(p) if limit == 0 else min(len(p), limit) for p in samples_points])
    K = int(counts.max())
    points = np.empty((M, K, 3), dtype=np.float32 if narrow else np.float64)
    mask = np.zeros((M, K), dtype=np.bool_)
    for j, p in enumerate(samples_points):
        q = _subsample(np.asarray(p), limit)
        if not np.all(np.isfinite(q)):
            raise InputError(f"profile {j} contains NaN or Inf: clean the profiles first")
        points[j, : len(q)] = q
        points[j, len(q) :] = q[0]
        mask[j, : len(q)] = True
    return CylinderProblem(
        points=points,
        mask=mask,
        counts=counts,
        R_bf=np.ascontiguousarray(T_all[:, :3, :3]),
        t_bf=np.ascontiguousarray(T_all[:, :3, 3]),
        estimate_radius=estimate_radius,
        config=config,
        estimate_scale=config.estimate_scale,
        estimate_depth_scale=config.estimate_depth_scale,
    )


def initial_state(
    problem: CylinderProblem, T_flange_sensor0: ArrayLike, cylinder0: Cylinder, radius: float
) -> CylinderState:
    """The start of the solve: the given hand-eye and axis, zero pose corrections.

    Raises
    ------
    InputError
        A start that is not a rigid transform, a degenerate axis or a bad radius.
    """
    try:
        T0 = check_transform(T_flange_sensor0, tolerance=1e-4)
    except ValueError as exc:
        raise InputError(f"the initial hand-eye is not a rigid transform: {exc}") from exc
    d = np.asarray(cylinder0.direction, dtype=np.float64)
    c = np.asarray(cylinder0.point, dtype=np.float64)
    if d.shape != (3,) or c.shape != (3,) or not np.all(np.isfinite(np.concatenate([c, d]))):
        raise InputError("the initial cylinder needs a finite point (3,) and direction (3,)")
    if not np.linalg.norm(d) > 0.0:
        raise InputError("the initial cylinder direction is zero")
    if not (np.isfinite(radius) and radius > 0.0):
        raise InputError(f"the cylinder radius must be a positive length in m, got {radius}")
    M = problem.n_samples
    return CylinderState(
        R_fs=T0[:3, :3].copy(),
        t_fs=T0[:3, 3].copy(),
        point=c,
        direction=d / np.linalg.norm(d),
        radius=float(radius),
        omega=np.zeros((M, 3)),
        tau=np.zeros((M, 3)),
    )


def lever_arm_m(problem: CylinderProblem) -> float:
    """Median distance of the profile points from the sensor origin, m."""
    lever = problem.config.observability.lever_m
    if lever is not None:
        return lever
    M, K = problem.mask.shape
    step = max(1, CHUNK_POINTS // K)  # a chunk at a time: no (M, K, 3) temporary
    real = problem.mask > 0.0
    # One array of the distances, its median taken in place: no list of chunks, no joined
    # or sorted copy (three arrays of every point's distance at once before).
    distances = np.empty(int(np.count_nonzero(real)))
    filled = 0
    for start in range(0, M, step):
        rows = slice(start, start + step)
        d = np.linalg.norm(np.asarray(problem.points[rows], dtype=np.float64), axis=2)[real[rows]]
        distances[filled : filled + d.size] = d
        filled += d.size
    return float(np.median(distances, overwrite_input=True))
