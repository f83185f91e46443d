"""The structured Newton matrix (contgrasp_core.rod.newton_matrix) against the dense truth: its
O(N^2) solve is backward stable and equals LAPACK's solve of the dense matrix on the paper run's
Newton systems and on random states; the structure itself is checked against the numpy reference path and finite
differences by test_kernels.py and test_rod_physics.py (both compare the dense form)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contgrasp_core.control import StateFeedback
from contgrasp_core.rod import RodLoads, RodState, _kernels
from contgrasp_core.rod.newton_matrix import ChainMatrix, dense
from contgrasp_core.rod.session import run_sampled
from contgrasp_core.scenario import PAPER
from test_rod_physics import _contact_case


def _check_solve(matrix: ChainMatrix, rhs: np.ndarray) -> None:
    """The structured solve is backward stable (its residual is a rounding of the dense matrix's
    entries: normwise backward error below 1e-15) and agrees with LAPACK's solve of the dense
    matrix to 1e-12 relative, or to what the condition number allows both (``cond * eps``; the
    paper run's worst Newton matrix, early in the approach, has cond ~ 1e9)."""
    a = matrix.dense()
    x = matrix.solve(rhs)
    ref = np.linalg.solve(a, rhs)
    backward = np.abs(rhs - a @ x).max() / (np.abs(a).sum(axis=1).max() * np.abs(x).max())
    assert backward < 1e-15
    cond = np.linalg.cond(a, np.inf)
    assert np.abs(x - ref).max() <= max(1e-12, cond * np.finfo(float).eps) * np.abs(ref).max()


def test_the_solve_equals_the_dense_solve_on_the_paper_runs_newton_systems(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every 10th Newton system of the paper run (the approach, the impact, the wrap and the
    settled grasp; N = 100, contact and the held feedback)."""
    assert _kernels.ENABLED
    seen: list[tuple[ChainMatrix, np.ndarray]] = []
    solve = ChainMatrix.solve

    def record(self: ChainMatrix, rhs: np.ndarray) -> np.ndarray:
        seen.append((self, rhs))
        return solve(self, rhs)

    monkeypatch.setattr(ChainMatrix, "solve", record)
    session = run_sampled(PAPER)
    assert session.k == 1097 and len(seen) == session.iterations
    monkeypatch.undo()
    for matrix, rhs in seen[::10]:
        _check_solve(matrix, rhs)


@pytest.mark.parametrize("method", ["euler", "midpoint"])
@pytest.mark.parametrize("feedback", ["none", "state", "held", "deformed"])
def test_the_solve_equals_the_dense_solve_on_random_states(method: str, feedback: str) -> None:
    """Random rates and increments of a rod pressed into the object, with damping, drag,
    friction, a held couple, node forces and every feedback (N = 14)."""
    system, state, loads = _contact_case(method, feedback)
    rng = np.random.default_rng(11)
    frame = system.contact_frame(state, 2e-3)
    for _ in range(10):
        w1 = state.omega + 5.0 * rng.standard_normal(len(state.omega))
        res, matrix, _ = system._newton_system(state, w1, 2e-3, loads, frame)
        assert isinstance(matrix, ChainMatrix)
        _check_solve(matrix, res)


@pytest.mark.parametrize("n", [50, 200, 400])
def test_the_solve_equals_the_dense_solve_at_larger_n(n: int) -> None:
    """The paper rod with N elements, randomly bent around its object and moving fast, under the
    continuous feedback law (StateFeedback) of the paper's gains."""
    scenario = replace(PAPER, rod=replace(PAPER.rod, n_elements=n))
    system = scenario.system()
    assert system.obstacle is not None
    loads = RodLoads(feedback=StateFeedback(scenario.rod, system.obstacle, scenario.feedback_gains))
    rng = np.random.default_rng(n)
    for _ in range(5):
        state = RodState(t=0.0, theta=np.cumsum(rng.uniform(0.0, 8.0 / n, n)), omega=rng.standard_normal(n))
        w1 = state.omega + 10.0 * rng.standard_normal(n)
        res, matrix, _ = system._newton_system(state, w1, 2e-3, loads, system.contact_frame(state, 2e-3))
        assert isinstance(matrix, ChainMatrix)
        _check_solve(matrix, res)


def test_dense_expands_the_upper_triangle_and_the_band() -> None:
    rng = np.random.default_rng(1)
    n = 6
    lower, left, up, band = rng.standard_normal((n, n)), rng.standard_normal((n, 2)), rng.standard_normal((n, 2)), rng.standard_normal(n)
    full = dense(ChainMatrix(lower, left, up, band))
    for j in range(n):
        for k in range(n):
            want = lower[j, k] if k <= j else left[j] @ up[k] + (band[j] if k == j + 1 else 0.0)
            assert full[j, k] == pytest.approx(want, rel=1e-15, abs=1e-15)


def test_a_vanishing_pivot_falls_back_to_lapack() -> None:
    """The elimination does not pivot: a zero leading entry (never a Newton matrix's) still gets
    the solution, by LAPACK with pivoting."""
    lower = np.array([[0.0, 0.0], [1.0, 2.0]])
    matrix = ChainMatrix(lower, np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[0.0, 0.0], [3.0, 0.0]]), np.zeros(2))
    rhs = np.array([3.0, 4.0])
    np.testing.assert_allclose(matrix.solve(rhs), np.linalg.solve(matrix.dense(), rhs), rtol=1e-15)
