"""One settings path: settings.py alone builds the pipeline's configuration from user
settings, and core messages name a setting neutrally, spelled by each front end."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.pipeline import Method
from linelaser_calib.core.targets.base import SETTINGS as TARGET_SETTINGS
from linelaser_calib.core.targets.base import rejection_digest
from linelaser_calib.core.types import Rejection
from linelaser_calib.nodes.calibration_service import PARAMETERS
from linelaser_calib.nodes.calibration_service import pipeline_config as service_config
from linelaser_calib.settings import SETTINGS, Front, pipeline_config, render

PACKAGE = Path(__file__).resolve().parent.parent / "linelaser_calib"
CORE = PACKAGE / "core"
#: A command-line flag in running text.
FLAG = re.compile(r"(?<![\w-])--[a-z]")


def service_values(**given: object) -> dict[str, object]:
    """The calibration service's parameter defaults with ``given`` set."""
    return {**{spec.name: spec.default for spec in PARAMETERS}, **given}


def test_only_settings_py_builds_a_pipeline_config_outside_core() -> None:
    builders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if CORE in path.parents or path == PACKAGE / "settings.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "PipelineConfig":
                builders.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert builders == []


def test_core_messages_name_no_command_line_flag() -> None:
    """String constants of core (docstrings aside) spell settings as placeholders."""
    flagged = []
    for path in sorted(CORE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        docstrings = {
            id(node.body[0].value)
            for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef))
            and node.body
            and isinstance(node.body[0], ast.Expr)
            and isinstance(node.body[0].value, ast.Constant)
        }
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in docstrings
                and FLAG.search(node.value)
            ):
                flagged.append(f"{path.relative_to(CORE)}:{node.lineno}: {node.value!r}")
    assert flagged == []


def test_every_target_setting_has_one_row_in_the_table() -> None:
    names = [s.name for s in SETTINGS]
    assert len(names) == len(set(names))
    assert set(TARGET_SETTINGS) <= set(names)
    parameters = {spec.name for spec in PARAMETERS}
    for setting in SETTINGS:
        if setting.parameter is not None and not setting.parameter.startswith("the collector"):
            assert setting.parameter in parameters, setting


def test_a_moving_scan_is_explained_in_each_front_ends_spelling() -> None:
    moving = [Rejection(k, k, "pairing", "robot moving at 0.2 m/s") for k in range(3)]
    digest = rejection_digest(moving)
    assert "give --max-speed 0 --max-angular-speed 0 and --clock-offset auto" in render(
        digest, Front.CLI
    )
    node = render(digest, Front.NODE)
    assert "the collector's max_linear_speed_m_s 0" in node
    assert "the collector's clock_offset_s auto" in node
    assert not FLAG.search(node) and "{setting:" not in node


def test_a_node_refusal_names_the_parameter_and_the_cli_refusal_the_flag() -> None:
    with pytest.raises(InputError) as node:
        service_config(service_values(target="known_point", radius=0.02))
    assert str(node.value).startswith("radius does not apply to the known point target")
    assert not FLAG.search(str(node.value))
    with pytest.raises(InputError) as cli:
        pipeline_config("known_point", Method.DEFAULT, {"radius_m": 0.02}, Front.CLI)
    assert str(cli.value).startswith("--radius does not apply to the known point target")


def test_the_node_and_the_command_line_build_the_same_configuration() -> None:
    values = service_values(radius=0.0125, min_samples=9, scale="free", seed=4, per_neighbourhood=7)
    node = service_config(values)
    cli = pipeline_config(
        "cylinder",
        Method.DEFAULT,
        {"radius_m": 0.0125, "min_samples": 9, "scale": "free"},
        Front.CLI,
        seed=4,
        per_neighbourhood=7,
    )
    assert node == cli and node.per_neighbourhood == 7
    assert node.target_config.radius_m == 0.0125 and node.target_config.scale == "free"


def test_an_initial_hand_eye_reaches_the_pipeline() -> None:
    T = np.eye(4)
    T[:3, 3] = [0.01, -0.02, 0.1]
    config = pipeline_config("cylinder", Method.DEFAULT, {"initial": T}, Front.CLI)
    assert config.initial_T_flange_sensor is not None
    np.testing.assert_allclose(config.initial_T_flange_sensor, T)
