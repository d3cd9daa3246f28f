"""ament_python package definition of linelaser_calib."""

import xml.etree.ElementTree as ET
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "linelaser_calib"
#: package.xml is the one source of the version; ``linelaser-calib --version`` reads it back
#: from the installed distribution's metadata.
VERSION = ET.parse(Path(__file__).parent / "package.xml").getroot().findtext("version")


def _share_tree(folder: str) -> list[tuple[str, list[str]]]:
    """data_files entries installing every file under ``folder`` into share/PACKAGE/."""
    entries: dict[str, list[str]] = {}
    for path in sorted(Path(folder).rglob("*")):
        if path.is_file():
            entries.setdefault(f"share/{PACKAGE}/{path.parent.as_posix()}", []).append(
                path.as_posix()
            )
    return sorted(entries.items())


setup(
    name=PACKAGE,
    version=VERSION,
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*", "msg_adapters", "msg_adapters.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        *_share_tree("config"),
        *_share_tree("bags"),
        *_share_tree("launch"),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="linelaser_calib maintainers",
    description="Hand-eye calibration of a line-laser profile sensor from cylinder scans.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "linelaser-calib = linelaser_calib.entry:main",
            "collector = linelaser_calib.entry:collector",
            "calibration_service = linelaser_calib.entry:calibration_service",
        ],
    },
)
