"""Shared output helpers so every subcommand prints JSON the same way, and values without Python reprs."""

from __future__ import annotations

import json
import sys
from typing import Any


def _default(obj: Any) -> Any:
    # numpy scalars and arrays, without importing numpy here
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "item"):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def na(value: object, unit: str = "") -> str:
    """A measured value for a person: ``n/a`` when it could not be measured (None), never ``None``."""
    return "n/a" if value is None else f"{value}{unit}"


def print_json(obj: Any, *, stream: Any = None, indent: int | None = None) -> None:
    """Print one JSON object on one line (or indented), numpy-aware."""
    out = stream if stream is not None else sys.stdout
    out.write(json.dumps(obj, default=_default, indent=indent) + "\n")
