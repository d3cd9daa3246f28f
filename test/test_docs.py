"""The guides run: every ``console`` command of README.md and docs/ works, every link resolves.

Which blocks run: fenced blocks whose info string is ``console``. In them, a line starting
with ``$ `` is a command (a trailing backslash continues it on the next line); other lines
are sample output and are ignored. Every command must be ``linelaser-calib ...``; it runs
through the console script's entry point in a subprocess, with the page's commands in order
in one temporary directory that holds a link ``bags`` to the committed bags, so a page writes
``--output result.yaml`` and reads ``bags/paper`` as a user does from the repository root. A
trailing ``> FILE`` sends the standard output to FILE. Blocks fenced as ``sh``, ``bash``,
``yaml`` or anything else (``ros2 launch``, ``ros2 run``, ``make``, long simulations) are not
run, nor is a block shown inside a longer fence (an example of the syntax).

Each command must exit 0; the files it writes (``--output``, a ``>`` redirect, the bag
directory of ``simulate``) must exist, and YAML ones must parse to a mapping; a command
that writes no file must print something.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: The console script's code (see setup.py's entry point).
ENTRY = "import sys; from linelaser_calib.entry import main; sys.exit(main())"
#: The front page stays a front page.
README_MAX_CHARS = 15_000
FENCE = re.compile(r"^(`{3,})(\S*)\s*$")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*$")


@dataclass(frozen=True)
class Command:
    """One documented command: its argv after ``linelaser-calib`` and where stdout goes."""

    line: int
    args: list[str]
    stdout_file: str | None

    def written_files(self) -> list[str]:
        """Files and directories the command writes, relative to its working directory."""
        out = [] if self.stdout_file is None else [self.stdout_file]
        for k, arg in enumerate(self.args):
            if arg == "--output" and k + 1 < len(self.args):
                out.append(self.args[k + 1])
            elif arg.startswith("--output="):
                out.append(arg.split("=", 1)[1])
        if self.args and self.args[0] == "simulate":
            out.append(next(a for a in self.args[1:] if not a.startswith("-")))
        return out


def _blocks(text: str) -> list[tuple[str, int, list[str]]]:
    """Top-level fenced blocks: (info string, first line number, lines)."""
    blocks: list[tuple[str, int, list[str]]] = []
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        opening = FENCE.match(lines[k])
        if opening is None:
            k += 1
            continue
        fence, info = opening.groups()
        body: list[str] = []
        k += 1
        while k < len(lines) and lines[k].strip() != fence:
            body.append(lines[k])
            k += 1
        blocks.append((info, k - len(body) + 1, body))
        k += 1
    return blocks


def console_commands(text: str) -> list[Command]:
    """The commands of the page's ``console`` blocks, in order."""
    commands: list[Command] = []
    for info, first, body in _blocks(text):
        if info != "console":
            continue
        k = 0
        while k < len(body):
            if not body[k].startswith("$ "):
                k += 1
                continue
            start, joined = first + k, body[k][2:]
            while joined.endswith("\\") and k + 1 < len(body):
                k += 1
                joined = joined[:-1] + " " + body[k].strip()
            k += 1
            words = shlex.split(joined)
            assert words[0] == "linelaser-calib", (
                f"line {start}: a console block runs only linelaser-calib commands; put "
                f"{words[0]!r} in a bash block"
            )
            stdout_file = None
            if ">" in words:
                at = words.index(">")
                stdout_file, words = words[at + 1], words[:at]
            commands.append(Command(start, words[1:], stdout_file))
    return commands


def _page_id(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


RUNNABLE = [page for page in PAGES if console_commands(page.read_text())]


def test_the_quick_start_and_the_guides_hold_runnable_commands() -> None:
    readme = [c.args[0] for c in console_commands((ROOT / "README.md").read_text())]
    assert "calibrate" in readme and "export" in readme
    assert len(RUNNABLE) >= 8, [_page_id(p) for p in RUNNABLE]


def test_the_readme_is_a_front_page() -> None:
    text = (ROOT / "README.md").read_text()
    assert len(text) <= README_MAX_CHARS
    assert text.startswith("# linelaser_calib\n\n```sh\nmake demo")


@pytest.mark.slow
@pytest.mark.parametrize("page", RUNNABLE, ids=_page_id)
def test_every_console_command_of_a_page_runs(page: Path, tmp_path: Path) -> None:
    (tmp_path / "bags").symlink_to(ROOT / "bags", target_is_directory=True)
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    for command in console_commands(page.read_text()):
        where = f"{_page_id(page)}:{command.line}: linelaser-calib {shlex.join(command.args)}"
        done = subprocess.run(
            [sys.executable, "-c", ENTRY, *command.args],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, f"{where}\nexited {done.returncode}:\n{done.stderr}"
        if command.stdout_file is not None:
            (tmp_path / command.stdout_file).write_text(done.stdout)
        written = command.written_files()
        if not written:
            assert done.stdout.strip(), f"{where}\nprinted nothing"
        for name in written:
            path = tmp_path / name
            assert path.exists(), f"{where}\ndid not write {name}"
            if path.suffix == ".yaml":
                assert isinstance(yaml.safe_load(path.read_text()), dict), f"{where}: {name}"
            elif path.is_file():
                assert path.stat().st_size > 0, f"{where}: {name} is empty"


def _anchors(page: Path) -> set[str]:
    """GitHub's anchors of the page's headings (outside fenced blocks)."""
    inside = {
        k for _, first, body in _blocks(page.read_text()) for k in range(first, first + len(body))
    }
    anchors = set()
    for number, line in enumerate(page.read_text().splitlines(), start=1):
        heading = HEADING.match(line)
        if heading is not None and number not in inside:
            anchors.add(re.sub(r"[^\w\- ]", "", heading.group(1).lower()).replace(" ", "-"))
    return anchors


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_every_relative_link_resolves(page: Path) -> None:
    blocks = _blocks(page.read_text())
    inside = {k for _, first, body in blocks for k in range(first - 1, first + len(body) + 1)}
    broken = []
    for number, line in enumerate(page.read_text().splitlines(), start=1):
        if number in inside:
            continue
        for target in LINK.findall(line):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            linked = page if not path else (page.parent / path).resolve()
            if not linked.exists():
                broken.append(f"line {number}: {target} (no such file)")
            elif anchor and linked.suffix == ".md" and anchor not in _anchors(linked):
                broken.append(f"line {number}: {target} (no such heading)")
    assert not broken, f"{_page_id(page)}: " + "; ".join(broken)
