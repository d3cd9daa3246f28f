"""YAML files of the package: written atomically, read with every problem naming the file and
the key (:class:`Fields`). The layouts (result, truth, reference, plan, kinematics, initial
hand-eye) live with their readers and writers; this is what they share."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from linelaser_calib.core.errors import InputError
from linelaser_calib.io.errors import ResultFileError

FloatArray = NDArray[np.float64]


def plain(value: Any) -> Any:
    """``value`` with numpy arrays and scalars turned into plain Python lists and numbers."""
    if isinstance(value, Mapping):
        return {plain(key): plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    return value


#: PyYAML's safe dumper with libyaml's emitter where PyYAML was built with it: the same text
#: (3,116 YAML files compared) in a quarter of the time (a 1,600-profile result's 60 kB:
#: 0.19 -> 0.06 s, after the solve on the critical path).
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def write_yaml_atomically(path: Path, header: str, data: dict[str, Any]) -> Path:
    """Write ``header`` + YAML of ``data`` to ``path`` via a flushed temporary file."""
    try:
        text = header + yaml.dump(
            data,
            Dumper=_DUMPER,
            sort_keys=False,
            default_flow_style=None,
            width=100,
            allow_unicode=True,
        )
    except yaml.YAMLError as err:
        raise InputError(f"cannot write {path}: a value is not plain YAML data: {err}") from err
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as stream:
                os.fchmod(stream.fileno(), 0o644)
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(tmp_name, path)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise
    except OSError as err:
        raise ResultFileError(f"cannot write {path}: {err}") from err
    return path


class Fields:
    """Typed access to a parsed YAML mapping; every problem names the file and the key."""

    def __init__(self, path: Path, data: Any, prefix: str = "") -> None:
        if not isinstance(data, dict):
            where = prefix.rstrip(".") or "the top level"
            raise ResultFileError(f"{path}: {where} must be a mapping, got {data!r}")
        self.path, self.data, self.prefix = path, data, prefix

    def error(self, key: object, problem: str) -> ResultFileError:
        return ResultFileError(f"{self.path}: key {self.prefix}{key} {problem}")

    def has(self, key: str) -> bool:
        return self.data.get(key) is not None

    def get(self, key: object) -> Any:
        if key not in self.data:
            raise self.error(key, "is missing")
        return self.data[key]

    def section(self, key: str) -> Fields:
        return Fields(self.path, self.get(key), f"{self.prefix}{key}.")

    def text(self, key: str) -> str:
        value = self.get(key)
        if not isinstance(value, str):
            raise self.error(key, f"must be a string, got {value!r}")
        return value

    def number(self, key: object) -> float:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f"must be a number, got {value!r}")
        return float(value)

    def integer(self, key: str) -> int:
        value = self.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"must be an integer, got {value!r}")
        return value

    def array(self, key: str, shape: tuple[int, ...]) -> FloatArray:
        value = self.get(key)
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.error(key, f"must be numbers of shape {shape}, got {value!r}") from None
        if array.shape != shape or not np.all(np.isfinite(array)):
            raise self.error(key, f"must be finite numbers of shape {shape}, got {value!r}")
        return array

    def items(self, key: str) -> list[Any]:
        """The list at ``key``; an absent or null key gives an empty list."""
        value = self.data.get(key)
        if value is None:
            return []
        if not isinstance(value, list):
            raise self.error(key, f"must be a list, got {value!r}")
        return value

    def integers(self, key: str) -> list[int]:
        values = self.items(key)
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            raise self.error(key, f"must be a list of integers, got {values!r}")
        return values

    def flag(self, key: str) -> bool:
        value = self.data.get(key, False)
        if not isinstance(value, bool):
            raise self.error(key, f"must be true or false, got {value!r}")
        return value


def load_fields(path: str | Path) -> tuple[Path, Fields]:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ResultFileError(f"{path} does not exist; check the path") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ResultFileError(f"cannot read {path}: {err}") from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ResultFileError(f"{path} is not valid YAML: {yaml_problem(err)}") from None
    return path, Fields(path, data)


def yaml_problem(err: yaml.YAMLError) -> str:
    """What a YAML parser found wrong and where (line and column, 1-based), without the
    parser's name for text it was handed (``"<unicode string>"``): the caller names the
    file."""
    if isinstance(err, yaml.MarkedYAMLError) and err.problem_mark is not None:
        mark = err.problem_mark
        context = f" ({err.context})" if err.context else ""
        return f"{err.problem}{context} at line {mark.line + 1}, column {mark.column + 1}"
    return str(err)
