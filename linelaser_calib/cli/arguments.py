"""Value types of the command line's options: each parses one word or raises
``argparse.ArgumentTypeError`` saying what was expected (SI units)."""

from __future__ import annotations

import argparse

import numpy as np


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (np.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return value


def seed(text: str) -> int:
    """A seed of the random stages: an integer from 0 to 2**32 - 1 (numpy's generators take
    no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0 to 2**32 - 1, got {text}")
    return value


def non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (np.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text}")
    return value


def _whole(text: str, low: int) -> int:
    """Parse a whole number >= ``low``."""
    expected = f"expected a whole number >= {low}"
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{expected}, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"{expected}, got {value}")
    return value


def non_negative_int(text: str) -> int:
    return _whole(text, 0)


def min_samples(text: str) -> int:
    """Parse a sample count >= 3."""
    return _whole(text, 3)


def offset(text: str) -> float | str:
    """Parse a clock offset in s, or ``auto``."""
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds or 'auto', got {text!r}") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected finite seconds, got {text!r}")
    return value


def centre_side(text: str) -> str:
    """Parse ``+y`` or ``-y``."""
    if text not in ("+y", "-y"):
        raise argparse.ArgumentTypeError(f"expected +y or -y, got {text!r}")
    return text


def named_numbers(text: str) -> dict[str, float]:
    """Parse ``NAME=VALUE,NAME=VALUE`` (numbers, SI)."""
    try:
        pairs = [part.split("=") for part in text.split(",")]
        values = {name.strip(): float(value) for name, value in pairs}
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE,NAME=VALUE, got {text!r}") from None
    if not all(np.isfinite(list(values.values()))):
        raise argparse.ArgumentTypeError(f"expected finite values, got {text!r}")
    return values


def xyz(text: str) -> tuple[float, float, float]:
    """Parse ``x,y,z`` (m)."""
    try:
        x, y, z = (float(p) for p in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,z in metres, got {text!r}") from None
    if not all(np.isfinite([x, y, z])):
        raise argparse.ArgumentTypeError(f"expected finite x,y,z in metres, got {text!r}")
    return x, y, z


def numbers(text: str) -> list[float]:
    """Parse comma-separated finite numbers."""
    try:
        values = [float(p) for p in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers a,b,..., got {text!r}") from None
    if not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def span(text: str) -> tuple[float, float]:
    """Parse ``lo,hi`` (m)."""
    values = numbers(text)
    if len(values) != 2 or not values[0] < values[1]:
        raise argparse.ArgumentTypeError(f"expected LO,HI in metres with LO < HI, got {text!r}")
    return values[0], values[1]


def sentinel(text: str) -> float:
    """Parse a sentinel depth, m (finite)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a depth in metres, got {text!r}") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(
            f"NaN and +-Inf are always no return; give a finite depth, got {text!r}"
        )
    return value
