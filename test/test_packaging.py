"""colcon build of the package, and its executables run the way ``ros2 run`` runs them."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from ros_helpers import (
    PACKAGE,
    REPO_ROOT,
    ColconInstall,
    colcon_install,
    new_domain_id,
    processes,
    ros_env,
    wait_for,
)

pytestmark = pytest.mark.ros

EXECUTABLES = ("collector", "calibration_service")


@pytest.fixture(scope="module")
def install(tmp_path_factory: pytest.TempPathFactory) -> ColconInstall:
    return colcon_install(tmp_path_factory.mktemp("colcon"))


def test_colcon_installs_executables_ament_index_and_share_files(install: ColconInstall) -> None:
    prefix = install.prefix
    for name in EXECUTABLES:
        assert (prefix / "lib" / PACKAGE / name).is_file(), name
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    share = prefix / "share" / PACKAGE
    for relative in (
        "package.xml",
        "config/collector.yaml",
        "config/calibration_service.yaml",
        "launch/linelaser_calib.launch.py",
        "launch/publish.launch.py",
    ):
        assert (share / relative).is_file(), relative
        assert (share / relative).read_bytes() == (REPO_ROOT / relative).read_bytes()


@pytest.mark.parametrize("name", EXECUTABLES)
def test_installed_script_runs_a_python_that_has_rclpy(install: ColconInstall, name: str) -> None:
    script = install.prefix / "lib" / PACKAGE / name
    shebang = script.read_text(encoding="utf-8").splitlines()[0]
    assert shebang.startswith("#!"), shebang
    interpreter = shebang[2:].split()[0]
    done = subprocess.run(
        [interpreter, "-c", "import rclpy, std_srvs.srv, numpy, scipy"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, f"{interpreter} cannot import rclpy: {done.stderr}"


def test_ros2_run_resolution_finds_the_installed_executables(install: ColconInstall) -> None:
    env = install.env(ros_env(new_domain_id()))
    for name in EXECUTABLES:
        assert install.executable(name, env) == install.prefix / "lib" / PACKAGE / name


def test_installed_executables_start_and_stop_cleanly(
    install: ColconInstall, tmp_path: Path
) -> None:
    domain = new_domain_id()
    env = install.env(ros_env(domain))
    share = install.prefix / "share" / PACKAGE / "config"
    with processes(tmp_path, domain) as group:
        service = group.start(
            "calibration_service",
            [
                str(install.executable("calibration_service", env)),
                "--ros-args",
                "--params-file",
                str(share / "calibration_service.yaml"),
            ],
            env,
        )
        collector = group.start(
            "collector",
            [
                str(install.executable("collector", env)),
                "--ros-args",
                "--params-file",
                str(share / "collector.yaml"),
                "-p",
                f"session_dir:={tmp_path / 'sessions'}",
            ],
            env,
        )
        wait_for(lambda: "to calibrate" in service.log(), 30.0, "the service to start")
        wait_for(lambda: "collecting in" in collector.log(), 30.0, "the collector to start")
        assert service.stop() == 0, service.log()
        assert collector.stop() == 0, collector.log()
        assert "Traceback" not in service.log() + collector.log()
    assert len(list((tmp_path / "sessions").glob("session_*"))) == 1


def test_a_bad_parameter_is_one_line_on_stderr_and_exit_status_1(
    install: ColconInstall, tmp_path: Path
) -> None:
    env = install.env(ros_env(new_domain_id()))
    done = subprocess.run(
        [
            str(install.executable("collector", env)),
            "--ros-args",
            "-p",
            "mode:=sideways",
            "-p",
            f"session_dir:={tmp_path}",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    assert "error: parameter mode is 'sideways'; it must be one of" in done.stderr
