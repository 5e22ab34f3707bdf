"""Stress: the stability cases of gaussim.bench.stability, each against its own criterion (its
docstring). The fast ones run with the suite; the long ones (1e6 steps, dt 1e-5) carry the ``long``
marker (``pytest -m long tests/stress``) and run in ``gaussim stability --long``, which writes
docs/stability.md.
"""

from __future__ import annotations

import pytest

from gaussim.bench.stability import cases, name

FAST = {name(case) for case in cases()}
CASES = [
    pytest.param(case, id=name(case), marks=[] if name(case) in FAST else [pytest.mark.long])
    for case in cases(long=True)
]


@pytest.mark.parametrize("case", CASES)
def test_stability_case(case):
    row = case()
    assert row.passed, f"{row.case}, {row.setting}: {row.result}"
