"""The command line itself (issue 24, part 3): its version, its help, its usage errors, the
scenarios and targets it offers, and a reader that leaves early.

Each verb's options are walked from the parser, so an option added later without help, unit
or default fails here.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import fields
from pathlib import Path
from typing import Any

import pytest

from linelaser_calib.cli import build_parser, calibrate, main
from linelaser_calib.cli.common import StderrProgress
from linelaser_calib.cli.simulate import SCENARIO_PRESETS
from linelaser_calib.core.targets import plannable_target_names, target_names
from linelaser_calib.sim import Scenario
from linelaser_calib.sim.recording import preset_names

REPO_ROOT = Path(__file__).resolve().parents[1]
#: The simulator's scenario fields, which a user never needs to see.
SCENARIO_FIELDS = {f.name for f in fields(Scenario)} - {"name"}
#: A unit a numeric option's help names (or the word "unitless").
UNIT = re.compile(r"(?<![\w/])(m|s|rad|deg|mm|m/s|rad/s|um|unitless)(?![\w/])")


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Every verb's parser, by name."""
    found: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            found.update(action.choices)
    return found


def is_numeric(action: argparse.Action) -> bool:
    """Whether an option's values are numbers: its type parses "1" or "1,2,3" as numbers."""
    if action.type is None or action.type is str or action.choices is not None:
        return False
    for text in ("1", "1,2,3", "1,2"):
        try:
            value = action.type(text)  # type: ignore[operator]
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            continue
        return isinstance(value, (int, float, tuple, list))
    return False


def test_version_is_the_package_xml_version(capsys: pytest.CaptureFixture[str]) -> None:
    expected = ET.parse(REPO_ROOT / "package.xml").getroot().findtext("version")
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"linelaser-calib {expected}"


def test_every_option_has_help_and_numeric_ones_name_unit_and_default() -> None:
    verbs = subparsers(build_parser())
    assert {"simulate", "calibrate", "plan", "reconstruct", "export", "demo"} <= set(verbs)
    missing: list[str] = []
    for verb, parser in verbs.items():
        for action in parser._actions:
            if not action.option_strings or isinstance(
                action, (argparse._HelpAction, argparse._VersionAction)
            ):
                continue
            name = f"{verb} {action.option_strings[0]}"
            text = (action.help or "") % {"default": action.default}
            if not text.strip():
                missing.append(f"{name}: no help")
            elif is_numeric(action):
                if not UNIT.search(text):
                    missing.append(f"{name}: no unit in {text!r}")
                if "default" not in text:
                    missing.append(f"{name}: no default in {text!r}")
            shown = f"{text} {action.metavar or ''}"
            own = action.option_strings[0].removeprefix("--").replace("-", "_")
            internal = action.dest in SCENARIO_FIELDS and action.dest != own
            if internal and action.dest.upper() in shown.upper():
                missing.append(f"{name}: the internal field name {action.dest} in {shown!r}")
    assert not missing, "\n".join(missing)


def test_scenario_help_and_refusal_list_every_preset(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert list(SCENARIO_PRESETS) == preset_names()
    assert len(preset_names()) >= 15
    code = main(["simulate", str(tmp_path / "bag"), "--scenario", "nope"])
    err = capsys.readouterr().err
    assert code == 1
    for name in preset_names():
        assert name in err
    assert not (tmp_path / "bag").exists()


def test_plan_offers_only_plannable_targets(capsys: pytest.CaptureFixture[str]) -> None:
    plan = subparsers(build_parser())["plan"]
    offered = next(a for a in plan._actions if "--target" in a.option_strings).choices
    assert offered is not None and tuple(offered) == plannable_target_names()
    refused = set(target_names()) - set(plannable_target_names())
    assert refused, "every target plans now: this test needs another refused target"
    with pytest.raises(SystemExit) as stop:
        main(["plan", "--target", sorted(refused)[0]])
    assert stop.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_usage_error_is_one_line_and_a_pointer_to_help(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["calibrate", "--radius", "-3"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert lines[0].startswith("linelaser-calib calibrate: error: ")
    assert lines[1:] == ["see 'linelaser-calib calibrate --help'"]


def test_a_reader_that_leaves_early_ends_the_output_quietly(tmp_path: Path) -> None:
    """``export ... | head -1``: no message, no traceback, exit 0 (docs/reference.md)."""
    result = tmp_path / "result.yaml"
    result.write_text(
        "hand_eye:\n  parent_frame: tool0\n  child_frame: laser\n"
        "  translation: [0.1, 0.02, 0.05]\n  rotation_xyzw: [0, 0, 0, 1]\n"
        "cylinder: {frame: base_link, point: [0, 0, 0], direction: [0, 0, 1], radius: 0.02}\n"
        "quality: {method: default, samples_used: [0, 1, 2], samples_rejected: [], "
        "rms_residual_m: 5.0e-6, warnings: []}\n",
        encoding="utf-8",
    )
    child = subprocess.Popen(
        [sys.executable, "-m", "linelaser_calib.cli", "export", str(result), "--format", "launch"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert child.stdout is not None and child.stderr is not None
    child.stdout.close()  # before the program starts writing: every write breaks the pipe
    err = child.stderr.read()
    assert child.wait(timeout=60) == 0
    assert err == b""


def test_ctrl_c_while_loading_ends_in_one_line(tmp_path: Path) -> None:
    """Ctrl-C in the first second (the libraries loading, or the bag being read): one line on
    stderr, exit 130, no traceback, no output."""
    out = tmp_path / "result.yaml"
    command = [str(Path(sys.executable).parent / "linelaser-calib"), "calibrate"]
    child = subprocess.Popen(
        [*command, str(REPO_ROOT / "bags" / "ur_scancontrol"), "--output", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(1.0)
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=60)
    assert child.returncode == 130
    assert err == "linelaser-calib: interrupted\n"
    assert not out.exists()


def test_ctrl_c_once_the_result_is_written_keeps_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C just after the result file is written: the run ends as written (exit 0, the
    file and its "Wrote" line), with a note that the interrupt came too late."""
    write = calibrate.write_result_yaml

    def write_then_interrupt(result: Any, path: Any) -> Path:
        written = write(result, path)
        os.kill(os.getpid(), signal.SIGINT)
        return written

    monkeypatch.setattr(calibrate, "write_result_yaml", write_then_interrupt)
    out = tmp_path / "result.yaml"
    bag = REPO_ROOT / "bags" / "weld_seam"
    argv = ["calibrate", str(bag), "--target", "known_point", "--output", str(out)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert f"Wrote {out}" in captured.out and out.exists()
    assert "interrupted after the outputs were written" in captured.err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


class _Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


class _Clock:
    """A clock that advances by ``tick`` s at every reading."""

    def __init__(self, tick: float) -> None:
        self.now, self.tick = 0.0, tick

    def __call__(self) -> float:
        self.now += self.tick
        return self.now


def test_progress_on_a_terminal_rewrites_one_line_and_estimates_the_time_left() -> None:
    """Each item of a 200-item stage takes 0.1 s: once the stage has run a second, the line
    says how long it has left (the truth, (200 - done) x 0.1 s, to a second); a line is
    drawn at most every half second and ends when its stage does."""
    terminal = _Terminal()
    progress = StderrProgress(True, terminal, _Clock(0.1))
    for done in range(201):
        progress("ellipse", done, 200)
    progress("refine", 0, 1)
    progress("refine", 1, 1)
    text = terminal.getvalue()
    updates = text.split("\r")[1:]
    assert 30 <= len(updates) <= 50  # 20 s of updates, every 0.5 s, plus the ends
    for update in updates:
        found = re.search(r"ellipse: (\d+)/200, about (\d+) s left", update)
        if found:
            done, left = int(found[1]), int(found[2])
            assert abs(left - (200 - done) * 0.1) <= 1.0
    assert "ellipse: 200/200\x1b[K\n" in text
    assert text.endswith("refine: 1/1\x1b[K\n")


def test_progress_elsewhere_writes_a_line_per_stage_start_and_end() -> None:
    """Redirected (a log, a pipe): no carriage return, no estimate; disabled: nothing."""
    log = io.StringIO()
    progress = StderrProgress(True, log, _Clock(0.1))
    for done in range(11):
        progress("ellipse", done, 10)
    lines = log.getvalue().splitlines()
    assert [line.split("] ")[1] for line in lines] == ["ellipse: 0/10", "ellipse: 10/10"]
    quiet = _Terminal()
    off = StderrProgress(False, quiet, _Clock(0.1))
    off("ellipse", 0, 10)
    assert quiet.getvalue() == ""
