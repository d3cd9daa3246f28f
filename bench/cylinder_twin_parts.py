"""Where the real cylinder twin's held-out difference between the tool and a plain fit comes
from (issue 29): each component of the two fits swapped, per held-out pose cluster.

The twin is ``bench/private_twins.py --only cylinder``'s (``cluttered_camera`` with its 120
profiles in 12 pose clusters, a 0.7 mm regional robot error field; seed 0 unless
``--seed``); each cluster is held out in turn and scored as there: the held-out cluster's
bar points (the simulator's labels) mapped with the recorded poses and a hand-eye, RMS
distance from the TRUE bar, um. Per cluster the columns are that figure for:

``tool``     the tool's hand-eye, its along-line scale removed from the points (as the
             twin scores it); ``tool GLS``: the same moved by one generalised-least-squares
             step under the robot error's sharing the tool learned (:func:`gls_hand_eye`, a
             probe of an estimate under that model); ``tool raw``: the tool's on the raw
             points.
``plain``    the plain fit (plain least squares over hand-eye, axis and free radius on the
             labelled arcs); ``plain+s``: the same on points with the tool's scale removed;
             ``plain R``: with the radius held at the truth.
``R given``  the tool run with the true radius given (``--radius``).
``true``     the true hand-eye (the robot's own share); ``common``: the true hand-eye with
             the training poses' mean robot error (the regional field's common part, flange
             frame) taken into it.
``oracle``   the best constant hand-eye for the training poses: fitted to the TRUE bar on the
             training clusters' labelled points (the floor of any hand-eye, judged here).

Then each hand-eye's displacement at the bar (the sensor point 1 m out, the distance the
bar is seen at) from the true one and from the ``common`` one, mm; against each fit's own
cylinder (``*``, what a real recording can measure) with the two fits' cylinders swapped,
um; and the tool's largest per-axis |error| / 1σ, from the true hand-eye and from
``common``. ``--without edge_bias_m robot_field_m``
sets those scenario fields to zero (attribution by cause). Run:
``OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/cylinder_twin_parts.py [--seed N]
[--without FIELD ...]`` (about 1.5 min of CPU, 3.5 min wall on a loaded machine).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from private_twins import (
    MIN_ARC_POINTS,
    _arc_points,
    _calibrate,
    _rms_from,
    error_over_sigma,
    plain_cylinder_fit,
)
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial.transform import Rotation

from linelaser_calib.core.geometry import FloatArray, exp_so3
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.shared_pose import (
    SharedPoseError,
    ViewsLinearised,
    correlation,
    pose_separations,
    shared_pose_error,
)
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.cylinder import shared as cylinder_shared
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.simulate import simulate

CLUSTERS = 12
_VIEWS: list[tuple[ViewsLinearised, SharedPoseError | None]] = []
#: The sensor-frame point at which a hand-eye's displacement is read: the bar's distance.
AT_BAR_M = np.array([0.0, 0.0, 1.0, 1.0])


def _mean_robot_error(T_recorded: FloatArray, T_true: FloatArray) -> FloatArray:
    """The mean flange-frame robot error of poses (K, 4, 4): inv(recorded) @ true, its
    translations averaged and its rotation vectors too (4, 4)."""
    E = np.linalg.inv(T_recorded) @ T_true
    out = np.eye(4)
    out[:3, :3] = Rotation.from_matrix(E[:, :3, :3]).mean().as_matrix()
    out[:3, 3] = E[:, :3, 3].mean(axis=0)
    return out


def _at_bar_mm(X: FloatArray, reference: FloatArray) -> float:
    return float(np.linalg.norm((X @ AT_BAR_M - reference @ AT_BAR_M)[:3]) * 1e3)


def gls_hand_eye(X: FloatArray, views: ViewsLinearised, shared: SharedPoseError) -> FloatArray:
    """The hand-eye ``X`` (4, 4) moved by one generalised-least-squares step from the
    per-view model the refinement solved (V₀ = I + A_j A_jᵀ per view) to the sharing it
    learned (V = s·I + a·exp(−d / ℓ) ∘ A Aᵀ), on its linearised ``views``: a probe of the
    estimate under the learned model, dense in (views × rows)²."""
    M, K, G = views.J_global.shape
    A, y, J = views.J_pose, views.residuals.ravel(), views.J_global.reshape(-1, G)
    T = views.T_base_flange
    flat = A.reshape(M * K, 6)
    row_view = np.repeat(np.arange(M), K)
    same = (row_view[:, None] == row_view[None, :]).astype(float)
    shared_corr = correlation(pose_separations(T, T), shared.length)[np.ix_(row_view, row_view)]
    steps = []
    for V in (
        np.eye(M * K) + same * (flat @ flat.T),
        shared.noise_factor * np.eye(M * K) + shared.amplitude * shared_corr * (flat @ flat.T),
    ):
        factor = cho_factor(V)
        H = J.T @ cho_solve(factor, J) + views.J_prior.T @ views.J_prior
        g = J.T @ cho_solve(factor, y) + views.J_prior.T @ views.prior
        steps.append(-np.linalg.solve(H, g))
    step = steps[1] - steps[0]
    out = X.copy()
    out[:3, :3] = X[:3, :3] @ exp_so3(step[:3])
    out[:3, 3] += step[3:6]
    return out


def _recording_views(
    views: ViewsLinearised, learned: SharedPoseError | None = None
) -> SharedPoseError | None:
    """:func:`shared_pose_error`, its views and result kept (the first of a run: the whole
    solve's)."""
    shared = shared_pose_error(views, learned)
    _VIEWS.append((views, shared))
    return shared


def _zero(value: object) -> object:
    """A scenario field's zero: 0.0, or a tuple of zeros."""
    return tuple(0.0 for _ in value) if isinstance(value, tuple) else 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--without",
        nargs="*",
        default=[],
        help="scenario fields set to zero (edge_bias_m, robot_field_m, lateral_scale_error, ...)",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    cylinder_shared.shared_pose_error = _recording_views  # the views of every solve
    scenario = scenario_from_preset("cluttered_camera", pose_clusters=CLUSTERS)
    zero = {name: _zero(getattr(scenario, name)) for name in args.without}
    data = simulate(replace(scenario, **zero), args.seed)
    samples = list(pair_profiles(data.profiles, data.poses, PairingConfig()).samples)
    truth, X_true, n = data.truth.cylinder, data.truth.T_flange_sensor, len(data.profiles)
    arcs = {s.index: _arc_points(data, s.index).astype(np.float64) for s in samples}
    heads = (
        "tool",
        "tool GLS",
        "tool raw",
        "plain",
        "plain+s",
        "plain R",
        "R given",
        "true",
        "common",
    )
    print(f"{'held':>4}" + "".join(f"{h:>9}" for h in (*heads, "oracle")), end="")
    print(
        "  at bar mm vs true: tool GLS plain common oracle | vs common: tool plain"
        "  * um: tool plain tool-Xp/Ap plain-Xp/At"
    )
    rows: list[FloatArray] = []
    for cluster in range(CLUSTERS):
        train = [s for s in samples if s.index * CLUSTERS // n != cluster]
        labelled = [s for s in train if len(arcs[s.index]) >= MIN_ARC_POINTS]
        held = [
            s
            for s in samples
            if s.index * CLUSTERS // n == cluster and len(arcs[s.index]) >= MIN_ARC_POINTS
        ]
        _VIEWS.clear()
        tool = _calibrate(train, "cylinder", {}, PairingConfig())
        views, shared = _VIEWS[0]
        given = _calibrate(train, "cylinder", {"radius_m": truth.radius}, PairingConfig())
        assert not isinstance(tool, str) and not isinstance(given, str)
        assert isinstance(tool.target, CylinderSection)
        assert isinstance(given.target, CylinderSection)
        T_train = [s.T_base_flange for s in labelled]
        raw_train = [arcs[s.index] for s in labelled]
        corrected_train = [tool.target.sensor_points(p) for p in raw_train]
        X_p, A_p = plain_cylinder_fit(
            T_train, raw_train, tool.T_flange_sensor, tool.target.cylinder
        )
        X_ps, _ = plain_cylinder_fit(
            T_train, corrected_train, tool.T_flange_sensor, tool.target.cylinder
        )
        X_pR, _ = plain_cylinder_fit(
            T_train, raw_train, tool.T_flange_sensor, tool.target.cylinder, radius=truth.radius
        )
        X_or, _ = plain_cylinder_fit(
            T_train, raw_train, X_true, truth, radius=truth.radius, axis=False
        )
        index = np.array([s.index for s in train])
        E_mean = _mean_robot_error(
            data.truth.T_base_flange_recorded[index], data.truth.T_base_flange_true[index]
        )
        X_common = E_mean @ X_true
        T_held = [s.T_base_flange for s in held]
        raw = [arcs[s.index] for s in held]
        fixed = [tool.target.sensor_points(p) for p in raw]
        fixed_given = [given.target.sensor_points(p) for p in raw]
        X_t, A_t = tool.T_flange_sensor, tool.target.cylinder
        X_gls = X_t if shared is None else gls_hand_eye(X_t, views, shared)
        figures = (
            _rms_from(T_held, fixed, X_t, truth),
            _rms_from(T_held, fixed, X_gls, truth),
            _rms_from(T_held, raw, X_t, truth),
            _rms_from(T_held, raw, X_p, truth),
            _rms_from(T_held, fixed, X_ps, truth),
            _rms_from(T_held, raw, X_pR, truth),
            _rms_from(T_held, fixed_given, given.T_flange_sensor, truth),
            _rms_from(T_held, raw, X_true, truth),
            _rms_from(T_held, raw, X_common, truth),
            _rms_from(T_held, raw, X_or, truth),
        )
        own = (
            _rms_from(T_held, fixed, X_t, A_t),
            _rms_from(T_held, raw, X_p, A_p),
            _rms_from(T_held, fixed, X_t, A_p),
            _rms_from(T_held, raw, X_p, A_t),
        )
        at_bar = [_at_bar_mm(X, X_true) for X in (X_t, X_gls, X_p, X_common, X_or)]
        at_bar += [_at_bar_mm(X, X_common) for X in (X_t, X_p)]
        print(
            f"{cluster:>4}"
            + "".join(f"{f * 1e6:>9.1f}" for f in figures)
            + "   "
            + " ".join(f"{a:.2f}" for a in at_bar)
            + "   "
            + " ".join(f"{o * 1e6:.1f}" for o in own)
            + f"   R tool {A_t.radius * 1e3:.3f} plain {A_p.radius * 1e3:.3f}"
            + f" scale {tool.target.scale or 0.0:+.4f}"
            + f"  |e|/1σ {error_over_sigma(tool, X_true):.2f}"
            + f" (vs common {error_over_sigma(tool, X_common):.2f})"
        )
        rows.append(np.r_[figures, at_bar])
    a = np.array(rows)
    print(
        "median"
        + "".join(f"{f * 1e6:>9.1f}" for f in np.median(a[:, :10], axis=0))
        + "   "
        + " ".join(f"{f:.2f}" for f in np.median(a[:, 10:], axis=0))
    )


if __name__ == "__main__":
    main()
