"""PLY point clouds: what CloudCompare, Open3D and MeshLab open.

Written as binary little-endian PLY 1.0: one ``vertex`` element with float32 ``x y z`` (m)
and, when given, float32 ``intensity``; a ``comment`` line names the frame and the unit.
:func:`read_ply` reads back vertex properties of binary little-endian and ASCII files
(float, double and integer types) of files whose first element is ``vertex``, enough
to check what was written.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from linelaser_calib.io.errors import ResultFileError

FloatArray = NDArray[np.float64]

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def write_ply(
    path: str | Path,
    points: FloatArray,
    *,
    frame_id: str,
    intensity: FloatArray | None = None,
) -> Path:
    """Write points (N, 3) in m, and optional intensities (N,), as a binary PLY file.

    The file is written to a hidden temporary name and renamed into place.

    Raises
    ------
    ResultFileError
        If the file cannot be written.
    """
    target = Path(path)
    xyz = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if intensity is not None:
        fields.append(("intensity", "<f4"))
    records = np.empty(len(xyz), dtype=fields)
    for axis, name in enumerate("xyz"):
        records[name] = xyz[:, axis]
    if intensity is not None:
        records["intensity"] = np.asarray(intensity, dtype=np.float64).reshape(-1)
    header = [
        "ply",
        "format binary_little_endian 1.0",
        f"comment linelaser_calib reconstruction, frame {frame_id}, unit m",
        f"element vertex {len(xyz)}",
        *(f"property float {name}" for name, _ in fields),
        "end_header",
    ]
    partial = target.with_name(f".{target.name}.partial")
    try:
        try:
            with partial.open("wb") as stream:
                stream.write(("\n".join(header) + "\n").encode("ascii"))
                stream.write(records.tobytes())
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(partial, target)
        finally:
            partial.unlink(missing_ok=True)
    except OSError as err:
        raise ResultFileError(f"cannot write {target}: {err.strerror or err}") from err
    return target


def read_ply(path: str | Path) -> dict[str, FloatArray]:
    """Vertex properties of a PLY file (binary little-endian or ASCII), as float64 arrays.

    Raises
    ------
    ResultFileError
        Missing file, not PLY, an unsupported format or a truncated body.
    """
    source = Path(path)
    try:
        data = source.read_bytes()
    except OSError as err:
        raise ResultFileError(f"cannot read {source}: {err.strerror or err}") from err
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise ResultFileError(f"{source} is not a PLY file")
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    body = data[end + len(b"end_header\n") :]
    fmt, count, props, in_vertex = "", 0, [], False
    for line in lines:
        words = line.split()
        if words[:1] == ["format"]:
            fmt = words[1]
        elif words[:1] == ["element"]:
            in_vertex = words[1] == "vertex"
            count = int(words[2]) if in_vertex else count
        elif words[:1] == ["property"] and in_vertex:
            if words[1] == "list" or words[1] not in _PLY_TYPES:
                raise ResultFileError(f"{source}: unsupported vertex property {line!r}")
            props.append((words[2], _PLY_TYPES[words[1]]))
    if fmt == "binary_little_endian":
        dtype = np.dtype([(name, "<" + code) for name, code in props])
        if len(body) < dtype.itemsize * count:
            raise ResultFileError(f"{source}: truncated PLY body")
        records = np.frombuffer(body, dtype=dtype, count=count)
        return {name: records[name].astype(np.float64) for name, _ in props}
    if fmt == "ascii":
        rows = body.decode("ascii").split("\n")[:count]
        table = np.array([[float(v) for v in row.split()] for row in rows]).reshape(count, -1)
        return {name: table[:, k] for k, (name, _) in enumerate(props)}
    raise ResultFileError(f"{source}: PLY format {fmt!r} is not supported")
