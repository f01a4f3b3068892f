"""Test parameters for faults the check sees that the data does not yet mend: each known one a strict xfail
naming what a person sees, so a mended clip must leave its list."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import pytest


def unknown_failures(clip: str, failures: Iterable[str], known: Mapping[str, Mapping[str, str]]) -> list[str]:
    """The check's ``failures`` of ``clip`` less those a known-fault table (per limit: ``{limit: {clip:
    what a person sees}}``) already records as strict xfails."""
    return [f for f in failures if clip not in known.get(f, {})]


def known_faults(names: Iterable[str], known: Mapping[str, str]) -> list[Any]:
    """``names`` as parameters, those in ``known`` marked strict xfail with its text as the reason."""
    return [
        pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=known[n])) if n in known else n
        for n in names
    ]
