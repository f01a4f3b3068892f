"""Opt-in pytest plugin (``-p trio_seed``, with ``tests/`` on ``PYTHONPATH``): seed trio's scheduler per test
and repeat tests, to replay a flake that depends on the order of ready tasks.

Trio runs each batch of ready tasks in either order at random (``trio._core._run._r``), so two writers woken
by one tick write in either order. TTES_TRIO_SEED=S runs the k-th test of the session with seed S + k
(printed with ``-rA``); TTES_REPEAT=n runs every test n times. Issue 21's failure replays with
``TTES_TRIO_SEED=1029`` on test_app_answer_encodes.py's first test alone (main before its fix).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator

import pytest
import trio._core._run as trio_run

_count = itertools.count()


@pytest.fixture(autouse=True)
def _trio_seed() -> Iterator[None]:
    seed = int(os.environ.get("TTES_TRIO_SEED", "0")) + next(_count)
    trio_run._r.seed(seed)
    yield
    print(f"trio seed {seed}")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    n = int(os.environ.get("TTES_REPEAT", "1"))
    if n > 1:
        metafunc.fixturenames.append("_repeat")
        metafunc.parametrize("_repeat", range(n))
