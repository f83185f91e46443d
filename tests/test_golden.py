"""The restructured code gives the numbers the code gave before it (tests/golden/cases.py).

The reference was computed on main at 3a13851 (before the package layout changed); it checks
that moving and renaming modules, the scenario model and the object syntax changed no physics.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent / "golden"))
import cases  # noqa: E402

REF = json.loads(cases.REFERENCE.read_text())


def close(got: object, want: object, atol: float, rtol: float) -> None:
    if isinstance(want, dict):
        assert isinstance(got, dict) and set(got) == set(want)
        for k in want:
            close(got[k], want[k], atol, rtol)
        return
    g = np.asarray(cases.jsonable(got), dtype=float)
    w = np.asarray(want, dtype=float)
    np.testing.assert_allclose(g, w, atol=atol, rtol=rtol, equal_nan=True)


@pytest.mark.heavy
@pytest.mark.parametrize("name,atol,rtol", [
    ("lockstep_paper_run", 1e-9, 0.0),        # metres and radians: within 1 nm
    ("closed_loop_continuous", 1e-9, 0.0),
    ("optimal_grasps", 1e-9, 1e-9),
    ("quality_maps", 0.0, 1e-8),
])
def test_same_numbers_as_before_the_restructure(name: str, atol: float, rtol: float) -> None:
    close(cases.CASES[name](), REF[name], atol, rtol)
