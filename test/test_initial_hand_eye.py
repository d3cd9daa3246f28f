"""The initial hand-eye in every form a user writes it, and clear refusals of bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from _compare import assert_floats_close

from linelaser_calib.cli import main
from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    rpy_from_matrix,
    transform_error,
    transform_from_rotation_translation,
    translation_quaternion_from_transform,
)
from linelaser_calib.io.errors import ResultFileError
from linelaser_calib.io.initial import read_initial_hand_eye
from linelaser_calib.io.results import read_result_yaml, read_truth_yaml

WELD = Path(__file__).resolve().parent.parent / "bags" / "weld_seam"


def elementary(axis: int, angle: float) -> np.ndarray:
    """Rotation about the fixed x (0), y (1) or z (2) axis, written out."""
    c, s = math.cos(angle), math.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


ROLL, PITCH, YAW = 0.3, -0.5, 2.0
#: R = Rz(yaw) Ry(pitch) Rx(roll), the ROS fixed-axis convention, built independently.
T_KNOWN = transform_from_rotation_translation(
    elementary(2, YAW) @ elementary(1, PITCH) @ elementary(0, ROLL), [0.012, -0.085, 0.095]
)


def numbers(values: np.ndarray, sep: str = " ") -> str:
    return sep.join(repr(float(v)) for v in values)


def written_forms(tmp_path: Path) -> dict[str, str]:
    """Each accepted form of T_KNOWN, as the text given to ``--initial``."""
    t, q = translation_quaternion_from_transform(T_KNOWN)
    rpy = [ROLL, PITCH, YAW]
    files = {
        # The hand-written file of a CAD or URDF user, exactly as in the bug report.
        "hand_eye_only": {
            "hand_eye": {
                "parent_frame": "tool0",
                "child_frame": "laser",
                "translation": t.tolist(),
                "rotation_xyzw": q.tolist(),
            }
        },
        "matrix_only": {"hand_eye": {"matrix": T_KNOWN.tolist()}},
    }
    forms = {}
    for name, content in files.items():
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(content))
        forms[name] = str(path)
    return {
        **forms,
        "seven_numbers": numbers(np.r_[t, q]),
        "seven_numbers_commas": numbers(np.r_[t, q], ", "),
        "six_numbers_rpy": numbers(np.r_[t, rpy]),
        "named_quaternion": "--x {} --y {} --z {} --qx {} --qy {} --qz {} --qw {}".format(
            *np.r_[t, q]
        ),
        "named_rpy": "--x {} --y {} --z {} --roll {} --pitch {} --yaw {}".format(*np.r_[t, rpy]),
    }


def test_every_form_gives_the_same_hand_eye(tmp_path: Path) -> None:
    for name, text in written_forms(tmp_path).items():
        T, warnings = read_initial_hand_eye(text)
        assert_floats_close(T, T_KNOWN, err_msg=name)
        assert warnings == [], name
    assert_floats_close(rpy_from_matrix(T_KNOWN[:3, :3]), [ROLL, PITCH, YAW])


def test_a_result_file_is_accepted() -> None:
    T, warnings = read_initial_hand_eye(str(WELD / "initial.yaml"))
    assert_floats_close(T, read_result_yaml(WELD / "initial.yaml").T_flange_sensor)
    assert warnings == []


def test_named_rotation_defaults_to_identity() -> None:
    T, _ = read_initial_hand_eye("--x 0.1 --z -0.05")
    assert_floats_close(T, transform_from_rotation_translation(np.eye(3), [0.1, 0.0, -0.05]))


def test_a_nearly_unit_quaternion_is_normalised_with_a_warning() -> None:
    T, warnings = read_initial_hand_eye("0.1 0.2 0.3 0 0 0.7071 0.7071")  # norm 0.99999
    assert len(warnings) == 1 and "normalised" in warnings[0] and "0.99999" in warnings[0]
    assert_floats_close(T[:3, :3], elementary(2, math.pi / 2))


def test_a_nearly_orthonormal_matrix_is_projected_with_a_warning(tmp_path: Path) -> None:
    path = tmp_path / "rounded.yaml"
    path.write_text(yaml.safe_dump({"hand_eye": {"matrix": np.round(T_KNOWN, 4).tolist()}}))
    T, warnings = read_initial_hand_eye(str(path))
    assert len(warnings) == 1 and "nearest rotation" in warnings[0]
    rotation, translation = transform_error(T, T_KNOWN)
    assert rotation < 1e-3 and translation < 1e-4


BAD = {
    "far_from_unit_quaternion": ("0.1 0.2 0.3 1 2 3 4", InputError, "norm 5.477"),
    "too_few_numbers": ("0.1 0.2 0.3 0 0", InputError, "got 5"),
    "too_many_numbers": ("0.1 0.2 0.3 0 0 0 1 0", InputError, "got 8"),
    "millimetres": ("150 200 250 0 0 0 1", InputError, "millimetres"),
    "degrees": ("0.1 0.2 0.3 0 0 90", InputError, "degrees"),
    "mixed_named_rotation": ("--x 0.1 --qw 1 --yaw 0.2", InputError, "--roll --pitch --yaw"),
    "repeated_named": ("--x 0.1 --x 0.2", InputError, "at most once"),
    "named_without_number": ("--x 0.1 --y", InputError, "named arguments"),
    "named_not_a_number": ("--x 0.1 --y one", InputError, "need numbers"),
    "missing_file": ("no/such/file.yaml", ResultFileError, "does not exist"),
}


@pytest.mark.parametrize(("text", "error", "message"), BAD.values(), ids=BAD.keys())
def test_bad_numbers_are_refused_with_a_clear_message(
    text: str, error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        read_initial_hand_eye(text)


BAD_FILES = {
    "no_rotation": ({"hand_eye": {"translation": [0.1, 0.2, 0.3]}}, "rotation_xyzw is missing"),
    "nothing": ({"hand_eye": {"parent_frame": "tool0"}}, "needs translation and rotation_xyzw"),
    "not_a_rotation": (
        {"hand_eye": {"matrix": np.diag([2.0, 2.0, 2.0, 1.0]).tolist()}},
        "not a rotation",
    ),
    "mm_matrix": (
        {"hand_eye": {"matrix": [[1, 0, 0, 150], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}},
        "millimetres",
    ),
    "disagreeing": (
        {
            "hand_eye": {
                "translation": [0, 0, 0],
                "rotation_xyzw": [0, 0, 0, 1],
                "matrix": [[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            }
        },
        "disagrees",
    ),
}


@pytest.mark.parametrize(("content", "message"), BAD_FILES.values(), ids=BAD_FILES.keys())
def test_bad_files_are_refused_naming_the_file(
    content: dict[str, object], message: str, tmp_path: Path
) -> None:
    path = tmp_path / "initial.yaml"
    path.write_text(yaml.safe_dump(content))
    with pytest.raises(ResultFileError, match=message) as caught:
        read_initial_hand_eye(str(path))
    assert str(path) in str(caught.value)


def test_calibrate_takes_the_numbers_of_a_static_transform(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The weld-seam paper method corrects the old hand-eye given as seven numbers."""
    initial = read_result_yaml(WELD / "initial.yaml")
    truth = read_truth_yaml(WELD / "truth.yaml")
    point = initial.target.to_mapping("base_link")["point"]
    t, q = translation_quaternion_from_transform(initial.T_flange_sensor)
    out = tmp_path / "result.yaml"
    argv = ["calibrate", str(WELD), "--target", "known_point", "--method", "paper"]
    argv += ["--point", ",".join(map(str, point))]
    assert main([*argv, "--initial", numbers(np.r_[t, q]), "--output", str(out)]) == 0
    rot0, trans0 = transform_error(initial.T_flange_sensor, truth.T_flange_sensor)
    rot, trans = transform_error(read_result_yaml(out).T_flange_sensor, truth.T_flange_sensor)
    assert rot < rot0 and trans < trans0
    capsys.readouterr()
    assert main([*argv, "--initial", "0.1 0.2 0.3 0 0 0.5 0.5"]) == 1
    assert "--initial" in capsys.readouterr().err


def test_every_verb_refuses_a_quaternion_typo_and_notes_a_rounded_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One digit typed wrong (0.156664 for 0.056664: 11 deg, norm 1.0106) after deleting the
    matrix is refused by export, plan --from, reconstruct and --initial alike, naming the
    field; the same quaternion rounded to 4 decimals is normalised with a note by each."""
    data = yaml.safe_load((WELD / "initial.yaml").read_text(encoding="utf-8"))
    del data["hand_eye"]["matrix"]
    q = np.array([-0.192126, -0.056664, 0.733059, 0.650001])
    typo = [-0.192126, -0.156664, 0.733059, 0.650001]
    for name, rotation in (("typo", typo), ("rounded", np.round(q / np.linalg.norm(q), 4))):
        data["hand_eye"]["rotation_xyzw"] = [float(v) for v in rotation]
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        cloud = str(tmp_path / f"{name}.ply")
        verbs = [
            ["export", str(path), "--format", "urdf"],
            ["plan", "--target", "cylinder", "--from", str(path), "--n", "1"],
            ["reconstruct", str(WELD), "--calibration", str(path), "--output", cloud],
        ]
        for argv in verbs:
            code = main(argv)
            err = capsys.readouterr().err
            assert "hand_eye.rotation_xyzw" in err, argv
            if name == "typo":
                assert code == 1 and "more than rounding its digits explains" in err, argv
            else:
                assert "normalised" in err, argv
        if name == "typo":
            with pytest.raises(ResultFileError, match=r"hand_eye.rotation_xyzw .* norm 1.0106"):
                read_initial_hand_eye(str(path))
        else:
            _, warnings = read_initial_hand_eye(str(path))
            assert len(warnings) == 1 and "normalised" in warnings[0]
