"""The demo: calibrate the committed bags with both methods and compare each hand-eye with
the bag's truth (simulated bags) or reference (real scans)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from linelaser_calib.cli.common import SETTING_FLAGS
from linelaser_calib.core.forked import available_workers
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import configure
from linelaser_calib.io.results import read_reference_yaml, read_result_yaml, truth_beside
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.summary import format_summary, hand_eye_seen


def preset_motion(name: object) -> str | None:
    """The motion (``step``, ``continuous``) of a simulator preset; None for another name."""
    from linelaser_calib.sim.line import LINE_PRESETS
    from linelaser_calib.sim.scenario import PRESETS
    from linelaser_calib.sim.sphere import SPHERE_PRESETS
    from linelaser_calib.sim.weld import WELD_PRESETS

    rigs = {
        **PRESETS,
        **{k: v.rig for k, v in WELD_PRESETS.items()},
        **{k: v.rig for k, v in LINE_PRESETS.items()},
        **{k: v.rig for k, v in SPHERE_PRESETS.items()},
    }
    rig = rigs.get(name) if isinstance(name, str) else None
    return None if rig is None else rig.motion


def demo_runs(bag: Path, seed: int, rows: list[tuple[str, str, float, float, float]]) -> None:
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
        config = PipelineConfig(
            method=method,
            target=target.name,
            target_config=configure(target, method.value, settings, SETTING_FLAGS),
            seed=seed,
            pairing=pairing,
            initial_T_flange_sensor=None if initial is None else initial.T_flange_sensor,
            workers=available_workers(),
        )
        started = time.perf_counter()
        run = calibrate_bag(bag, config, estimate_offset=continuous)
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
