"""Start-up: a command loads what it needs when it needs it.

Checked by the modules loaded (deterministic), not by timing; ``bench/startup.py`` measures
the time.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parent.parent
#: Heavy modules no calibration of a cylinder recording needs: plotting, ROS, and every ROS
#: distribution's message types (the recording carries its own definitions).
NOT_NEEDED = ("matplotlib", "rclpy", "rosbags.typesys.stores.ros2_jazzy")

PROBE = """
import json, sys
loaded = lambda: sorted(m for m in sys.modules if m.startswith(NOT_NEEDED))
NOT_NEEDED = tuple(sys.argv[1:])
import linelaser_calib.cli
after_import = loaded()
code = linelaser_calib.cli.main(["calibrate", "bags/paper", "--json"])
print(json.dumps({"import": after_import, "calibrate": loaded(), "code": code}))
"""


def probe(script: str, *args: str, env: dict[str, str] | None = None) -> dict[str, Any]:
    """The JSON report a script prints last, run in a fresh interpreter in the repository."""
    run = subprocess.run(
        [sys.executable, "-c", script, *args],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    report: dict[str, Any] = json.loads(run.stdout.splitlines()[-1])
    return report


def test_the_cli_and_a_calibration_load_no_plotting_or_ros() -> None:
    report = probe(PROBE, *NOT_NEEDED)
    assert report["code"] == 0
    assert report["import"] == [], "imported by linelaser_calib.cli"
    assert report["calibrate"] == [], "imported by calibrate bags/paper"


ENTRY_PROBE = """
import json, sys
from linelaser_calib.entry import main
sys.argv = ["linelaser-calib", "info", "bags/paper"]
code = main()
import os
status = open("/proc/self/status").read() if os.path.exists("/proc/self/status") else ""
threads = [int(line.split()[1]) for line in status.splitlines() if line.startswith("Threads:")]
blas = os.environ.get("OPENBLAS_NUM_THREADS")
print(json.dumps({"code": code, "blas": blas, "threads": threads}))
"""


NODE_PROBE = """
import json, os, sys, types
from linelaser_calib import entry
seen = {}
def stand_in(name):
    seen[name] = os.environ.get("OPENBLAS_NUM_THREADS")
    return 0
for name in ("collector", "calibration_service"):
    module = types.ModuleType("linelaser_calib.nodes." + name)
    module.main = lambda name=name: stand_in(name)
    sys.modules[module.__name__] = module
    getattr(entry, name)()
print(json.dumps({"blas": seen, "numpy": "numpy" in sys.modules}))
"""


def test_the_console_script_runs_one_blas_thread_unless_the_user_chose() -> None:
    for preset, expected in ((None, "1"), ("2", "2")):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
        if preset is not None:
            env["OPENBLAS_NUM_THREADS"] = preset
        report = probe(ENTRY_PROBE, env=env)
        assert report["code"] == 0
        assert report["blas"] == expected
        if preset is None and report["threads"]:
            assert report["threads"] == [1], "the process runs BLAS threads"
        # The nodes' console scripts set it too, before anything loads numpy.
        nodes = probe(NODE_PROBE, env=env)
        assert nodes["blas"] == {"collector": expected, "calibration_service": expected}
        assert not nodes["numpy"]
