"""The demo: calibrate the committed bags with both methods and compare each hand-eye with
the bag's truth (simulated bags) or reference (real scans)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.forked import available_workers
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method
from linelaser_calib.core.targets import get_target
from linelaser_calib.io.results import read_reference_yaml, read_result_yaml, truth_beside
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.settings import Front, pipeline_config, render_warnings
from linelaser_calib.sim.recording import preset_motion
from linelaser_calib.summary import format_summary, hand_eye_seen

#: A row of the demo's table: bag, method and reference, rotation error (deg), translation
#: error (mm), calibration time (s).
DemoRow = tuple[str, str, float, float, float]


def run_demo(root: Path, seed: int) -> list[DemoRow]:
    """Calibrate every bag under ``root`` (:func:`demo_runs`) and return the table's rows.

    Raises
    ------
    InputError
        No bag under ``root``.
    """
    bags = sorted(p.parent for p in root.glob("*/metadata.yaml"))
    if not bags:
        raise InputError(f"no rosbag2 bags found under {root}; run from the repository root")
    rows: list[DemoRow] = []
    for bag in bags:
        demo_runs(bag, seed, rows)
    return rows


def format_demo_table(rows: list[DemoRow]) -> str:
    """The demo's table: each hand-eye's difference to the truth or reference (deg, mm)."""
    lines = [
        "Difference of the hand-eye T_flange_sensor to the truth (simulated bags) or to the",
        "reference (real scans: another tool's published hand-eye, not ground truth):",
        f"  {'bag':<24}{'method':<22}{'rotation deg':>14}{'translation mm':>16}{'time s':>9}",
    ]
    for name, label, rot_deg, trans_mm, seconds in rows:
        lines.append(f"  {name:<24}{label:<22}{rot_deg:>14.4f}{trans_mm:>16.4f}{seconds:>9.2f}")
    return "\n".join(lines)


def demo_runs(bag: Path, seed: int, rows: list[DemoRow]) -> None:
    """Calibrate one committed bag with both methods, print the summaries, add table rows.

    A simulated bag is compared with its ``truth.yaml`` (and, with ``initial.yaml``,
    corrects that hand-eye; a continuous scan is calibrated as one, at any flange speed with
    the clock offset estimated); a converted real recording with its ``reference.yaml``
    (another tool's hand-eye, calibrated with the settings recorded there). A bag with
    neither is skipped with a note.
    """
    settings: dict[str, object] = {}
    initial = None
    continuous = False
    truth, note = truth_beside(bag)
    if truth is None and not (bag / "reference.yaml").is_file():
        print(note or f"{bag} has no truth.yaml or reference.yaml; skipped", file=sys.stderr)
        return
    if truth is not None:
        target = get_target(truth.target.key)
        compare, against = truth.T_flange_sensor, "truth"
        label = target.title
        if (bag / "initial.yaml").is_file():
            initial = read_result_yaml(bag / "initial.yaml")
            settings = {**initial.target.given_settings(), "initial": initial.T_flange_sensor}
            label += ", from initial.yaml"
            rot, trans = transform_error(initial.T_flange_sensor, truth.T_flange_sensor)
            rows.append((bag.name, "initial", np.degrees(rot), trans * 1e3, 0.0))
        continuous = preset_motion(truth.raw.get("simulation", {}).get("scenario")) == "continuous"
        if continuous:
            label += ", continuous, clock offset estimated"
    else:
        compare, reference = read_reference_yaml(bag / "reference.yaml")
        target = get_target(str(reference["target"]))
        settings = dict(reference.get("settings") or {})
        against = "reference"
        label = f"{target.title}, real scans; reference.yaml is not ground truth"
    pairing = (
        PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)
        if continuous
        else PairingConfig()
    )
    for method in (Method.PAPER, Method.DEFAULT):
        config = pipeline_config(
            target.name,
            method,
            settings,
            Front.CLI,
            seed=seed,
            pairing=pairing,
            workers=available_workers(),
        )
        started = time.perf_counter()
        run = calibrate_bag(bag, config, estimate_offset=continuous)
        render_warnings(run.result, Front.CLI)
        seconds = time.perf_counter() - started
        print(f"=== {bag.name} ({label}), method {method.value} ({seconds:.2f} s) ===")
        print(format_summary(run.result, truth))
        seen = compare if truth is None else hand_eye_seen(truth, run.result.kinematics)
        rot, trans = transform_error(run.result.T_flange_sensor, seen)
        if truth is None:
            print(
                f"Difference to the reference hand-eye: rotation {np.degrees(rot):.4f} deg, "
                f"translation {trans * 1e3:.4f} mm (not ground truth)"
            )
        print()
        rows.append(
            (bag.name, f"{method.value} vs {against}", np.degrees(rot), trans * 1e3, seconds)
        )
