"""Comparisons of computed floats that last-bit differences between machines cannot fail.

Floats computed on another CPU, or through another code path of the same math library,
may differ in the last bits (about 1e-16 relative) even with pinned versions. These helpers
compare them with tolerances far above that and far below any change of behaviour; ints,
bools, strings, None, keys and lengths are compared exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

#: Relative tolerance for float64 values: ~4500 last-bit steps, far below any real change.
RTOL = 1e-12
#: Absolute tolerance, m for lengths (1 nm); unitless and angular values are far above it.
ATOL = 1e-9
#: One float32 rounding step, relative: a float64 value that moved by its last bits may round
#: to the neighbouring float32 (points in PointCloud2 are float32).
FLOAT32_RTOL = float(np.finfo(np.float32).eps)


def assert_floats_close(
    actual: ArrayLike,
    expected: ArrayLike,
    *,
    rtol: float = RTOL,
    atol: float = ATOL,
    err_msg: str = "",
) -> None:
    """Assert equal shapes, NaN at the same places, and values within the tolerances."""
    a, e = np.asarray(actual, dtype=np.float64), np.asarray(expected, dtype=np.float64)
    assert a.shape == e.shape, f"{err_msg}: shape {a.shape} != {e.shape}"
    np.testing.assert_allclose(a, e, rtol=rtol, atol=atol, equal_nan=True, err_msg=err_msg)


def assert_float32_close(actual: ArrayLike, expected: ArrayLike, *, err_msg: str = "") -> None:
    """:func:`assert_floats_close` for values stored as float32: one rounding step apart."""
    assert_floats_close(actual, expected, rtol=FLOAT32_RTOL, err_msg=err_msg)


def assert_trees_close(actual: Any, expected: Any, where: str = "") -> None:
    """Assert that two parsed YAML/JSON trees are equal, floats within the tolerances.

    Keys, lengths, strings, bools, ints and None must be equal; a float on either side is
    compared with :func:`assert_floats_close`.
    """
    here = where or "the top level"
    if isinstance(expected, dict):
        assert isinstance(actual, dict), f"{here}: {actual!r} is not a mapping"
        assert list(actual) == list(expected), f"{here}: keys {list(actual)} != {list(expected)}"
        for key, value in expected.items():
            assert_trees_close(actual[key], value, f"{where}.{key}" if where else str(key))
    elif isinstance(expected, list):
        assert isinstance(actual, list), f"{here}: {actual!r} is not a list"
        assert len(actual) == len(expected), f"{here}: length {len(actual)} != {len(expected)}"
        for i, (a, e) in enumerate(zip(actual, expected, strict=True)):
            assert_trees_close(a, e, f"{where}[{i}]")
    elif isinstance(expected, float) or (isinstance(actual, float) and type(expected) is int):
        assert type(actual) in (int, float), f"{here}: {actual!r} is not a number"
        assert_floats_close(actual, expected, err_msg=here)
    else:
        assert type(actual) is type(expected) and actual == expected, (
            f"{here}: {actual!r} != {expected!r}"
        )
