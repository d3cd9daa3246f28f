"""A self-contained HTML report of a calibration: ``index.html`` plus PNG figures beside it.

The page references its figures by relative file names and carries its style inline, so the
report folder can be copied or mailed as a whole. Text comes from
:mod:`linelaser_calib.summary` (the same wording as the CLI summary); the figures from
:mod:`linelaser_calib.report.figures`, imported only here, after checking that matplotlib is
installed.
"""

from __future__ import annotations

import datetime
import html
import importlib.util
import os
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.base import feature_residuals
from linelaser_calib.core.verdict import verdict_of, warning_kind
from linelaser_calib.io.results import Truth
from linelaser_calib.report.data import ReportData, report_data
from linelaser_calib.report.errors import ReportError
from linelaser_calib.summary import (
    Rows,
    hand_eye_rows,
    headline_rows,
    rejection_lines,
    residual_kind,
    residual_rows,
    samples_line,
    self_check_rows,
    target_text,
    truth_rows,
    warning_reference,
)

INDEX = "index.html"

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1040px; color: #222;
       line-height: 1.4; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0; }
th, td { text-align: left; padding: 0.2em 1em 0.2em 0; vertical-align: top; }
th { font-weight: 600; white-space: nowrap; }
td { font-family: ui-monospace, monospace; }
.warning { background: #fff4e0; border-left: 4px solid #e69500; padding: 0.4em 0.8em;
           margin: 0.4em 0; }
.ok { color: #2a7a2a; }
.verdict { font-size: 1.05em; border: 2px solid #2a7a2a; padding: 0.4em 0.8em; }
.verdict.use_with_care { border-color: #e69500; background: #fff4e0; }
.verdict.do_not_use { border-color: #b00020; background: #fde8ea; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #555; }
"""


def require_matplotlib() -> None:
    """Raise ReportError when matplotlib, which draws the figures, is not installed."""
    if importlib.util.find_spec("matplotlib") is None:
        raise ReportError(
            "the HTML report needs matplotlib, which is not installed; install it "
            "(pip install matplotlib, or apt install python3-matplotlib) or leave out --report"
        )


def _table(rows: Rows) -> str:
    cells = "".join(
        f"<tr><th>{html.escape(label)}</th><td>{html.escape(text)}</td></tr>"
        for label, text in rows
    )
    return f"<table>{cells}</table>"


def _items(lines: list[str], css: str = "") -> str:
    return "".join(f'<div class="{css}">{html.escape(line)}</div>' for line in lines)


def _warnings(result: CalibrationResult) -> str:
    """Each warning's whole text, headed by its stable id, which is also its paragraph's
    anchor in the warnings guide."""
    return "".join(
        f'<div class="warning"><b>{html.escape(warning_kind(text).id)}</b> '
        f"({html.escape(warning_reference(k, text))}): {html.escape(text)}</div>"
        for k, text in enumerate(result.warnings)
    )


def _residual_rows(result: CalibrationResult, data: ReportData) -> Rows:
    """Each residual number of the report, named by what it measures, in µm."""
    title = result.target.title
    rows = [
        (
            "fit residual",
            f"{result.rms_residual_m * 1e6:.1f} um RMS over {len(result.samples_used)} samples: "
            f"{residual_kind(result)} (the quantity the {result.method} method minimised)",
        ),
        (
            "recorded-pose residual",
            f"{data.recorded_pose_rms_m * 1e6:.1f} um RMS: distance of each "
            f"{'point' if data.per_point else 'feature point'} from the fitted {title} with the "
            "recorded flange poses, robot pose error included (the residual figure below)",
        ),
    ]
    features = feature_residuals(result.target)
    if features is not None and data.feature_distances_m is not None:
        values = data.feature_distances_m
        rms = float(np.sqrt(np.mean(values**2))) if values.size else float("nan")
        rows.append(
            ("feature residual", f"{rms * 1e6:.1f} um RMS: {features.feature_kind}, recorded poses")
        )
    return rows + residual_rows(result)[1:]


def _page(
    result: CalibrationResult,
    data: ReportData,
    inputs: Sequence[tuple[str, str]],
    truth: Truth | None,
    created: datetime.datetime,
    figures: list[tuple[str, str, str]],
) -> str:
    """The HTML text; ``figures`` holds (file, title, caption) of the written PNGs."""
    method = "maximum likelihood (default)" if result.method == "default" else result.method
    header: Rows = [
        ("target", result.target.title),
        *inputs,
        ("method", method),
        ("created", created.isoformat(timespec="seconds")),
    ]
    state = verdict_of(result).level.value
    title = result.target.title
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>linelaser_calib report: {html.escape(title)} target</title>",
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>Line-laser hand-eye calibration: {html.escape(title)} target</h1>",
        f'<div class="verdict {state}">{_table(headline_rows(result))}</div>',
        _table(header),
        f"<h2>Hand-eye T_flange_sensor ({html.escape(result.parent_frame)} &rarr; "
        f"{html.escape(result.child_frame)})</h2>",
        _table(hand_eye_rows(result)),
        f"<h2>The {html.escape(title)} and the residuals</h2>",
        f"<p>{html.escape(target_text(result))}</p>",
        _table(_residual_rows(result, data)),
        "<h2>Self-check</h2>",
        _table(self_check_rows(result))
        if result.self_check is not None
        else f"<p>not run: {html.escape(result.self_check_skipped_because or 'unknown')}</p>",
        "<h2>Samples</h2>",
        f"<p>{html.escape(samples_line(result))}.</p>",
        _items(rejection_lines(result)),
        "<h2>Warnings</h2>",
        _warnings(result) if result.warnings else '<p class="ok">none</p>',
    ]
    if truth is not None:
        parts += ["<h2>Error against truth</h2>", _table(truth_rows(result, truth))]
    for file, heading, caption in figures:
        parts += [
            f"<h2>{html.escape(heading)}</h2>",
            f'<figure><img src="{html.escape(file)}" alt="{html.escape(heading)}">',
            f"<figcaption>{html.escape(caption)}</figcaption></figure>",
        ]
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def write_report(
    directory: str | Path,
    result: CalibrationResult,
    *,
    inputs: Sequence[tuple[str, str]] = (),
    truth: Truth | None = None,
    created: datetime.datetime | None = None,
) -> Path:
    """Write ``index.html`` and its PNG figures into ``directory``.

    Parameters
    ----------
    directory : str or Path
        Created if missing; files of an earlier report there are replaced.
    result : CalibrationResult
        With ``sample_fits`` (the figures are drawn from them).
    inputs : list of (label, text)
        What was calibrated (bag path, topics, counts), shown first.
    truth : Truth, optional
        When given, the error against it is shown.
    created : datetime, optional
        Time shown on the page; default now (local time zone).

    Returns
    -------
    Path
        The ``index.html`` written.

    Raises
    ------
    ReportError
        matplotlib is missing or the directory cannot be written.
    """
    require_matplotlib()
    from linelaser_calib.report.figures import figures_of

    out = Path(directory)
    data = report_data(result)
    created_dir = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        written: list[tuple[str, str, str]] = []
        for spec in figures_of(data):
            spec.build(data).savefig(out / spec.file, format="png")
            written.append((spec.file, spec.title, spec.caption))
        stamp = created or datetime.datetime.now().astimezone()
        index = out / INDEX
        partial = out / f".{INDEX}.partial"
        try:
            partial.write_text(_page(result, data, inputs, truth, stamp, written), encoding="utf-8")
            os.replace(partial, index)
        finally:
            partial.unlink(missing_ok=True)
    except OSError as err:
        if created_dir:
            shutil.rmtree(out, ignore_errors=True)
        raise ReportError(f"cannot write the report into {out}: {err.strerror or err}") from err
    return index
