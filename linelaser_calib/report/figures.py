"""Matplotlib figures of a calibration result, rendered off-screen (Agg, no pyplot state).

Importing this module imports matplotlib; :func:`linelaser_calib.report.html.write_report`
imports it only after checking that matplotlib is installed. Every figure is built from a
:class:`ReportData` (the result plus its residuals, computed once through the result
section's protocol, :class:`~linelaser_calib.core.targets.base.ResultSection`, so that every
target has a report) and :func:`figures_of` lists those that apply, in page order. A target
section's optional capabilities add their figures: the unrolled residual map
(:func:`~linelaser_calib.core.targets.base.surface_map`) and the paper's feature residual
(:func:`~linelaser_calib.core.targets.base.feature_residuals`).

Lengths are shown in mm and residuals in µm, each axis labelled with its unit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from linelaser_calib.core.geometry import FloatArray, orthonormal_basis
from linelaser_calib.core.offset_search import OFFSET_COSTS, OFFSET_TRIALS
from linelaser_calib.core.planning import SigmaPoint
from linelaser_calib.core.targets.base import Shape, feature_residuals
from linelaser_calib.report.data import ReportData

matplotlib.use("Agg")

#: Figure width, inches; at :data:`DPI` the PNGs are 1000 px wide.
WIDTH_IN = 10.0
DPI = 100
#: Points drawn in the 3-D view at most (evenly strided per sample).
MAX_3D_POINTS = 6000
#: Colour map of the signed residuals (blue inside, red outside the surface).
RESIDUAL_CMAP = "RdBu_r"


def _figure(height_in: float) -> Figure:
    return Figure(figsize=(WIDTH_IN, height_in), dpi=DPI, layout="constrained")


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def _legend_above(ax: Axes) -> None:
    """The legend above the axes, right-aligned, where it covers no data."""
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=3, frameon=False)


def _profile_axis(ax: Axes, text: str = "profile index") -> None:
    """Label the x axis as profile indices, ticked at whole numbers."""
    ax.set_xlabel(text)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def _mark_rejected(ax: Axes, data: ReportData) -> None:
    """Mark each rejected profile (x at the foot of the axes) so that it is no silent gap,
    and widen the profile axis to hold them and the used ones."""
    rejected = np.array([r.index for r in data.result.samples_rejected], dtype=np.intp)
    if not len(rejected):
        return
    ax.scatter(
        rejected,
        np.full(len(rejected), 0.03),
        transform=ax.get_xaxis_transform(),
        marker="x",
        s=18,
        color="tab:red",
        label=f"rejected ({len(rejected)}; reasons in the Samples section)",
    )
    every = np.concatenate([data.indices, rejected])
    ax.set_xlim(float(every.min()) - 1.0, float(every.max()) + 1.0)
    _legend_above(ax)


def feature_distance_figure(data: ReportData) -> Figure:
    """Stem plot of each sample's feature residual (e.g. ellipse centre to axis), µm."""
    fig = _figure(3.6)
    ax = fig.add_subplot()
    values = np.zeros(0) if data.feature_distances_m is None else data.feature_distances_m * 1e6
    if len(values):
        ax.stem(data.indices, values, basefmt=" ")
        rms = float(np.sqrt(np.mean(values**2)))
        ax.axhline(rms, color="tab:red", lw=1, ls="--", label=f"RMS {rms:.1f} µm")
        _legend_above(ax)
        ax.set_ylim(bottom=0.0)
    else:
        _no_data(ax, "no fitted samples")
    _mark_rejected(ax, data)
    _profile_axis(ax)
    ax.set_ylabel("distance, µm")
    ax.grid(True, alpha=0.3)
    return fig


def sample_residual_figure(data: ReportData) -> Figure:
    """Each sample's distances from the fitted target, µm: a box per sample when they are of
    its points, a stem when there is one per sample (its feature point)."""
    fig = _figure(3.8)
    ax = fig.add_subplot()
    residuals = [d * 1e6 for d in data.distances_m]
    if not residuals:
        _no_data(ax, "no fitted samples")
    elif data.per_point:
        ax.boxplot(
            residuals,
            positions=data.indices,
            widths=0.6,
            whis=(5.0, 95.0),
            flierprops={"markersize": 2, "alpha": 0.4},
            medianprops={"color": "tab:red"},
        )
        ax.axhline(0.0, color="0.3", lw=0.8)
        step = max(1, len(data.indices) // 25)
        ax.set_xticks(data.indices[::step], [str(i) for i in data.indices[::step]])
    else:
        values = np.array([float(r[0]) for r in residuals])
        ax.stem(data.indices, values, basefmt=" ")
        rms = float(np.sqrt(np.mean(values**2)))
        ax.axhline(rms, color="tab:red", lw=1, ls="--", label=f"RMS {rms:.1f} µm")
        _legend_above(ax)
        ax.set_ylim(bottom=0.0)
    if residuals:
        _mark_rejected(ax, data)
    if data.per_point:
        ax.set_xlabel("profile index (box: quartiles, whiskers: 5 % to 95 %)")
        ax.set_ylabel("point to surface, µm (+ outside)")
    else:
        _profile_axis(ax)
        ax.set_ylabel("distance, µm")
    ax.grid(True, axis="y", alpha=0.3)
    return fig


def _draw_shape(ax: Any, shape: Shape) -> FloatArray:
    """Draw one marker shape (mm) in a 3-D axes (``Axes3D``); returns points (K, 3) in mm
    that bound it."""
    points = np.asarray(shape.points, dtype=np.float64) * 1e3
    radius = shape.radius * 1e3
    color = shape.color[:3]
    if shape.kind == "cylinder":
        start, end = points[0], points[1]
        d = end - start
        u, v = orthonormal_basis(d / np.linalg.norm(d))
        angle, along = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0.0, 1.0, 9))
        ring = np.cos(angle)[..., None] * u + np.sin(angle)[..., None] * v
        surface = start + radius * ring + along[..., None] * d
        ax.plot_wireframe(*np.moveaxis(surface, -1, 0), color="0.55", lw=0.5, alpha=0.6)
        return np.asarray(surface.reshape(-1, 3), dtype=np.float64)
    if shape.kind == "sphere":
        theta, phi = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0, np.pi, 19))
        unit = np.stack(
            [np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=-1
        )
        surface = points[0] + radius * unit
        ax.plot_wireframe(*np.moveaxis(surface, -1, 0), color="0.55", lw=0.5, alpha=0.6)
        return np.asarray(surface.reshape(-1, 3), dtype=np.float64)
    if shape.kind == "line":
        for start, end in points.reshape(-1, 2, 3):
            ax.plot(*np.stack([start, end]).T, color="tab:red", lw=3.0, zorder=10)
        return points
    ax.scatter(
        points[:, 0],
        points[:, 1],
        points[:, 2],
        s=250,
        color=color,
        edgecolors="k",
        marker="*",
        depthshade=False,
    )
    return points


def profiles_3d_figure(data: ReportData) -> Figure:
    """3-D view of the profiles in the base frame with the fitted target's shapes, mm."""
    fig = _figure(7.0)
    # matplotlib types the 3-D axes as plain Axes; its 3-D methods are used here.
    ax: Any = fig.add_subplot(projection="3d")
    bounds = []
    if data.points_base:
        per_sample = max(1, MAX_3D_POINTS // len(data.points_base))
        shown = [p[:: max(1, int(np.ceil(len(p) / per_sample)))] * 1e3 for p in data.points_base]
        index = np.concatenate(
            [np.full(len(p), i) for p, i in zip(shown, data.indices, strict=True)]
        )
        points = ax.scatter(
            *np.concatenate(shown).T, s=1, c=index, cmap="cividis", alpha=0.5, depthshade=False
        )
        fig.colorbar(points, ax=ax, shrink=0.6, label="profile index")
        bounds += shown
    for shape in data.result.target.shapes(data.all_points_base):
        bounds.append(_draw_shape(ax, shape))
    corners = np.concatenate(bounds) if bounds else np.zeros((1, 3))
    # Each axis spans its data (at least a tenth of the widest), one mm as long on all three:
    # a flat sweep gives a flat box, not a cube mostly empty.
    span = np.ptp(corners, axis=0)
    span = np.maximum(span, max(0.1 * float(np.max(span)), 1.0)) * 1.05
    middle = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
    ax.set_xlim(middle[0] - span[0] / 2, middle[0] + span[0] / 2)
    ax.set_ylim(middle[1] - span[1] / 2, middle[1] + span[1] / 2)
    ax.set_zlim(middle[2] - span[2] / 2, middle[2] + span[2] / 2)
    # Zoomed out a little so that the z label, drawn outside the box, stays in the figure.
    ax.set_box_aspect(tuple(span / np.max(span)), zoom=0.85)
    for axis, length in zip((ax.xaxis, ax.yaxis, ax.zaxis), span / np.max(span), strict=True):
        axis.set_major_locator(MaxNLocator(max(2, round(7 * float(length)))))
    frame = data.result.base_frame
    ax.set_xlabel(f"x ({frame}), mm")
    ax.set_ylabel(f"y ({frame}), mm")
    ax.set_zlabel(f"z ({frame}), mm")
    return fig


def _map_values(values: FloatArray, unit: str) -> tuple[FloatArray, str]:
    """Values in the unit shown: rad as deg, m as mm."""
    if unit == "rad":
        return np.degrees(values), "deg"
    return values * 1e3, "mm"


def residual_map_figure(data: ReportData) -> Figure:
    """The target's unrolled surface: two surface coordinates, coloured by residual."""
    fig = _figure(4.8)
    ax = fig.add_subplot()
    surface = data.surface
    residual_um = data.all_distances_m * 1e6
    if surface is None or not len(residual_um):
        _no_data(ax, "no fitted samples")
        return fig
    across, across_unit = _map_values(surface.across, surface.across_unit)
    along, along_unit = _map_values(surface.along, surface.along_unit)
    limit = max(float(np.percentile(np.abs(residual_um), 99)), 1e-3)
    points = ax.scatter(
        across, along, c=residual_um, s=3, cmap=RESIDUAL_CMAP, vmin=-limit, vmax=limit
    )
    fig.colorbar(points, ax=ax, label="point to surface, µm (+ outside)", extend="both")
    if surface.across_unit == "rad":
        ax.set_xlim(-180.0, 180.0)
        ax.set_xticks(np.arange(-180, 181, 45))
    ax.set_xlabel(f"{surface.across_label}, {across_unit}")
    ax.set_ylabel(f"{surface.along_label}, {along_unit}")
    ax.grid(True, alpha=0.3)
    return fig


def self_check_figure(data: ReportData) -> Figure:
    """The self-check's held-out RMS per region of the workspace, µm, with the accuracy in use
    (left), and the pose-interleaved held-out RMS per profile, a consistency check (right)."""
    fig = _figure(3.6)
    check = data.result.self_check
    if check is None or not len(check.indices):
        _no_data(fig.add_subplot(), "no self-check")
        return fig
    regions, interleaved = fig.subplots(1, 2, width_ratios=(1, 2))
    if check.region_rms_m is None or check.accuracy_in_use_m is None:
        _no_data(
            regions,
            f"{check.regions or 'fewer than 3'} regions:\nno accuracy in use can be measured",
        )
    else:
        values = np.asarray(check.region_rms_m) * 1e6
        sizes = [len(members) for members in check.region_indices]
        labels = [f"{k + 1}\n({n})" for k, n in enumerate(sizes)]
        regions.bar(np.arange(len(values)), values, tick_label=labels, color="tab:blue")
        accuracy = check.accuracy_in_use_m * 1e6
        regions.axhline(
            accuracy, color="tab:red", lw=1, ls="--", label=f"accuracy in use {accuracy:.1f} µm"
        )
        regions.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), frameon=False)
        regions.set_xlabel("region held out (profiles)")
        regions.set_ylabel("held-out RMS distance, µm")
        regions.set_ylim(bottom=0.0)
        regions.grid(True, axis="y", alpha=0.3)
    values = np.asarray(check.held_out_rms_m) * 1e6
    interleaved.stem(np.asarray(check.indices), values, basefmt=" ")
    consistency = check.interleaved_rms_m * 1e6
    interleaved.axhline(
        consistency,
        color="0.4",
        lw=1,
        ls=":",
        label=f"pose-interleaved {consistency:.1f} µm RMS (consistency check)",
    )
    _legend_above(interleaved)
    interleaved.set_ylim(bottom=0.0)
    _profile_axis(interleaved, "profile index (held out of the solve that mapped it)")
    interleaved.grid(True, alpha=0.3)
    return fig


#: A trace spanning at least this ratio is drawn on a log axis, a flatter one on a linear axis.
LOG_SCALE_RATIO = 10.0


def _plot_traces(ax: Axes, traces: list[tuple[str, list[float]]], scale: float) -> bool:
    """Plot convergence traces (values times ``scale``) against their iteration.

    The axis is logarithmic when the positive values span at least :data:`LOG_SCALE_RATIO`
    (non-positive values are then left out). Otherwise each trace is drawn as its change from
    its final value, which its legend states: a cost that changes by 1e-4 of itself is then
    readable. Returns True for a logarithmic axis, False for changes from the final value.
    """
    arrays = [(label, np.asarray(v, dtype=np.float64) * scale) for label, v in traces if len(v)]
    values = np.concatenate([y for _, y in arrays])
    positive = values[values > 0.0]
    log = len(positive) > 0 and positive.max() >= LOG_SCALE_RATIO * positive.min()
    for label, y in arrays:
        if log:
            ax.plot(np.arange(len(y)), np.where(y > 0.0, y, np.nan), ".-", lw=1.2, label=label)
        else:
            ax.plot(
                np.arange(len(y)), y - y[-1], ".-", lw=1.2, label=f"{label} (final {y[-1]:.6g})"
            )
    if log:
        ax.set_yscale("log")
    else:
        ax.axhline(0.0, color="0.3", lw=0.8)
    ax.legend(loc="best", fontsize="small", framealpha=0.8)
    return log


@dataclass(frozen=True)
class TracePanel:
    """One panel of the convergence figure: history keys, their labels, scale and axes."""

    title: str
    traces: tuple[tuple[str, str], ...]
    scale: float
    xlabel: str
    ylabel: str
    violation: str = ""


#: The convergence panels, each drawn when the result's history holds one of its traces.
TRACE_PANELS: tuple[TracePanel, ...] = (
    TracePanel(
        "PSO (paper Fig. 5)",
        (("pso_best", "f_best"),),
        1e6,
        "PSO generation",
        "best fitness, mm²",
    ),
    TracePanel(
        "GALM (paper Fig. 6)",
        (("galm_f", "f, centre to axis (minimised)"), ("galm_phi", "φ, augmented merit")),
        1e6,
        "GALM outer iteration (runs joined)",
        "mm²",
        violation="galm_h",
    ),
    TracePanel(
        "Paper's translation shift",
        (("paper_delta_r_m", "mean offset"),),
        1e3,
        "iteration",
        "shift, mm",
    ),
    TracePanel(
        "ML refinement",
        (("refine_cost", "cost"),),
        1.0,
        "Levenberg-Marquardt step",
        "robust cost, dimensionless",
    ),
)


def _panels(history: dict[str, list[float]]) -> list[TracePanel]:
    return [p for p in TRACE_PANELS if any(history.get(key) for key, _ in p.traces)]


def convergence_figure(data: ReportData) -> Figure:
    """One panel per solver stage that recorded a trace (see :data:`TRACE_PANELS`), stacked."""
    history = data.result.history
    panels = _panels(history)
    fig = _figure(1.0 + 2.6 * len(panels))
    axes = fig.subplots(len(panels), 1, squeeze=False)[:, 0]
    for ax, panel in zip(axes, panels, strict=True):
        traces = [(label, history.get(key, [])) for key, label in panel.traces]
        log = _plot_traces(ax, traces, panel.scale)
        violation = [v for v in history.get(panel.violation, []) if v > 0.0]
        if violation:
            twin = ax.twinx()
            twin.semilogy(violation, ".:", color="0.4", lw=1.0)
            twin.set_ylabel("constraint violation ‖h‖ (dotted), dimensionless")
        ax.set_title(panel.title, loc="left")
        ax.set_xlabel(panel.xlabel)
        ax.set_ylabel(panel.ylabel if log else f"change from the final,\n{panel.ylabel}")
        ax.grid(True, which="both", alpha=0.3)
    return fig


def convergence_caption(data: ReportData) -> str:
    """What the convergence panels show, and which solver stages recorded no trace."""
    history = data.result.history
    parts = [
        "Each solver stage's trace per iteration; traces spanning a factor of 10 or more are "
        "drawn on a log scale, flatter ones as their change from the final value (given in "
        "the legend)."
    ]
    if history.get("galm_phi"):
        parts.append(
            "In the GALM panel f, the centre-to-axis objective, is minimised subject to the "
            "unit-norm constraints h(x) = 0 (eq. 11), and φ = f − λᵀh + σ/2 ‖h‖² is the augmented "
            "Lagrangian's merit (eq. 14). Either may rise a little from one outer iteration to "
            "the next while the multipliers λ and the penalty σ are updated and the constraint "
            "violation ‖h‖ (dotted, right axis) falls: that is the constraint being met, not "
            "divergence."
        )
    if "pso_best" in history and not history["pso_best"]:
        parts.append(
            "No PSO generation ran: a particle of the initial swarm, polished, was already "
            "within the acceptance bound, so the seed was taken from it."
        )
    return " ".join(parts)


def clock_offset_figure(data: ReportData) -> Figure:
    """The clock offsets the estimate tried against the target's cost, ms, with the chosen
    one (the cost on a log axis where it spans a factor of 10, else as its change from the
    lowest)."""
    result = data.result
    fig = _figure(3.4)
    ax = fig.add_subplot()
    offsets = np.asarray(result.history.get(OFFSET_TRIALS, []), dtype=np.float64) * 1e3
    costs = np.asarray(result.history.get(OFFSET_COSTS, []), dtype=np.float64)
    lowest = float(costs.min())
    if lowest > 0.0 and float(costs.max()) >= LOG_SCALE_RATIO * lowest:
        ax.semilogy(offsets, costs, ".-", lw=1.0, label="tried")
        ax.set_ylabel("target cost, dimensionless")
    else:
        ax.plot(offsets, costs - lowest, ".-", lw=1.0, label=f"tried (lowest {lowest:.6g})")
        ax.set_ylabel("target cost − lowest, dimensionless")
    chosen = result.clock_offset_s * 1e3
    ax.axvline(chosen, color="tab:red", lw=1.2, ls="--", label=f"estimate {chosen:+.2f} ms")
    ax.set_xlabel("clock offset added to the profile stamps, ms")
    ax.grid(True, alpha=0.3)
    _legend_above(ax)
    return fig


@dataclass(frozen=True)
class FigureSpec:
    """One figure of the report: PNG file name, heading, caption and builder."""

    file: str
    title: str
    caption: str
    build: Callable[[ReportData], Figure]


def figures_of(data: ReportData) -> list[FigureSpec]:
    """The report's figures for this result, in page order."""
    title = data.result.target.title
    specs = []
    features = feature_residuals(data.result.target)
    if features is not None and data.feature_distances_m is not None:
        specs.append(
            FigureSpec(
                "centre_distances.png",
                f"Feature residual per sample: {features.feature_kind}",
                "Each profile's feature point, mapped into the base frame with its recorded "
                "flange pose and the calibrated hand-eye, and its distance from the fitted "
                f"{title}.",
                feature_distance_figure,
            )
        )
    what = "inlier point" if data.per_point else "feature point"
    specs.append(
        FigureSpec(
            "point_residuals.png",
            "Residual per sample (recorded poses)",
            f"Distance of each {what} from the fitted {title}, mapped with the recorded flange "
            "poses (no per-sample pose correction), so the robot's pose error is included: "
            "these are larger than the fit residual, which corrects each pose.",
            sample_residual_figure,
        )
    )
    specs.append(
        FigureSpec(
            "profiles_3d.png",
            f"Profiles and the {title} in the base frame",
            "T_base_flange · T_flange_sensor · p for every point the fit used, coloured by "
            f"profile index, with the fitted {title} (grey wireframe, red line or star); one mm "
            "is as long on every axis.",
            profiles_3d_figure,
        )
    )
    if data.surface is not None and data.per_point:
        specs.append(
            FigureSpec(
                "residual_map.png",
                "Unrolled residual map",
                f"The {title}'s surface unrolled: each point at its two surface coordinates, "
                "coloured by its signed distance to the surface (red outside, blue inside). A "
                "pattern that follows a coordinate points to a model error (wrong radius, bent "
                "axis, a scale error); random colours are noise.",
                residual_map_figure,
            )
        )
    if data.result.self_check is not None:
        specs.append(
            FigureSpec(
                "self_check.png",
                "Self-check: held-out regions and profiles",
                "Left: each region of the workspace held out in turn, its profiles mapped with "
                "their recorded poses and the hand-eye solved without the region; the RMS over "
                "the regions is the accuracy in use, what scans elsewhere in the cell will "
                "show. Right: each profile held out of pose-interleaved folds, whose "
                "neighbours stay in the solve; only a consistency check, it does not see an "
                "error that neighbouring poses share.",
                self_check_figure,
            )
        )
    if data.result.clock_offset_estimated and data.result.history.get(OFFSET_TRIALS):
        specs.append(
            FigureSpec(
                "clock_offset.png",
                "Clock offset estimate",
                "The target's cost with the profiles paired at each clock offset tried (a grid, "
                "then a golden-section search about its best): a clear minimum is a well "
                "determined offset; a flat curve means the flange stood still and no offset can "
                "be seen.",
                clock_offset_figure,
            )
        )
    if _panels(data.result.history):
        specs.append(
            FigureSpec(
                "convergence.png", "Convergence", convergence_caption(data), convergence_figure
            )
        )
    return specs


def sigma_curve_figure(predicted: list[SigmaPoint], achieved: list[SigmaPoint]) -> Figure:
    """The hand-eye's largest per-axis 1σ against the number of poses: predicted by the
    planner (line) and achieved by calibrations (markers); translation in mm, rotation in
    deg, log scales."""
    fig = _figure(3.6)
    panels = fig.subplots(1, 2)
    for column, (ax, scale, unit) in enumerate(
        zip(panels, (1e3, float(np.degrees(1.0))), ("mm", "deg"), strict=True)
    ):
        for series, style, label in ((predicted, "-o", "predicted"), (achieved, "s", "achieved")):
            if series:
                poses = [n for n, *_ in series]
                values = [float(np.max(sigmas[column])) * scale for _, *sigmas in series]
                ax.plot(poses, values, style, ms=4, label=label)
        ax.set_yscale("log")
        ax.set_xlabel("poses")
        ax.set_ylabel(f"largest 1 sigma of the {('translation', 'rotation')[column]}, {unit}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper right")
    return fig
