"""Small helpers for writing MJCF text."""
from __future__ import annotations


def vector(values) -> str:
    """Numbers as an MJCF attribute value ("x y z ..."), 9 significant digits."""
    return " ".join(f"{float(v):.9g}" for v in values)
