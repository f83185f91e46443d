"""The graph started by hand in any order: the four installed executables, started in the
orders of a Latin square (the rotations of a seeded shuffled order: every node first once and
last once, every pair in both orders) with random gaps, never lose step 0, and each run is the
core loop's bit for bit (the graph, its probe and the reference run are tests/test_by_hand.py's).
A file of its own, so the test command's two workers share the by-hand runs instead of one
worker doing them all."""

from __future__ import annotations

import os
import random
import time
from typing import Any

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("contgrasp_msgs.msg")

import test_by_hand as by_hand  # noqa: E402 - the by-hand graph and its fixtures
from contgrasp_core.scenario import NODES  # noqa: E402

Graph = by_hand.Graph
graph = by_hand.graph
paper_core = by_hand.paper_core
same_as_core = by_hand.same_as_core

# The orders and gaps come from this seed (printed; set
# CONTGRASP_BY_HAND_SEED to replay them; CI's HYPOTHESIS_PROFILE=ci fixes it as it fixes the
# property tests' draws).
BY_HAND_SEED = int(os.environ.get("CONTGRASP_BY_HAND_SEED")
                   or (0 if os.environ.get("HYPOTHESIS_PROFILE") == "ci" else random.SystemRandom().randrange(2**32)))
BY_HAND_RUNS = int(os.environ.get("CONTGRASP_BY_HAND_RUNS") or len(NODES))
"""Starts per test run: one Latin square of orders (more: further squares, each from the next seeded order)."""
MAX_GAP_S = 1.5


@pytest.mark.heavy
@pytest.mark.parametrize("run", range(BY_HAND_RUNS))
def test_four_nodes_by_hand_in_any_order_with_any_gaps_never_lose_step_0(graph: Graph, paper_core: Any, run: int) -> None:
    """The four executables, no parameter file, started in a shuffled order 0-1.5 s
    apart: step 0 reaches the loop every time (no couple timeout, no fallback), so the run is
    the core loop's bit for bit with zero missed deadlines, whichever node comes last; every
    node then exits by itself with status 0. (Whole runs: a short one can end before the last
    node is up, and a node that never hears the end never exits by itself.)"""
    square, turn = divmod(run, len(NODES))
    order = list(NODES)
    random.Random(f"{BY_HAND_SEED}:square {square}").shuffle(order)
    order = order[turn:] + order[:turn]  # (the square's rows: a rotation each)
    rng = random.Random(f"{BY_HAND_SEED}:{run}")
    starts = list(zip(order, [*(rng.uniform(0.0, MAX_GAP_S) for _ in order[1:]), 0.0], strict=True))  # (node, gap after it)
    plan = f"seed {BY_HAND_SEED} run {run}: " + ", ".join(f"{node} +{gap:.2f} s" for node, gap in starts)
    print(f"by hand, {plan} (replay: CONTGRASP_BY_HAND_SEED={BY_HAND_SEED} -k 'never_lose_step_0 and [{run}]')")
    for node, gap in starts:
        # (min_subscribers 3: this test's probe too, as in tests/test_by_hand.py, so it hears the
        # run to its end; on_finish exit: every node ends itself when the run is over)
        graph.start(node, "--ros-args", "-p", "on_finish:=exit",
                    *(("-p", "min_subscribers:=3") if node == "rod_simulator" else ()))
        time.sleep(gap)  # a person starting the next terminal
    assert graph.spin_until(lambda: graph.status.get("state") == "finished", timeout=240), (plan, graph.post_mortem())
    assert graph.spin_until(lambda: graph.last is not None and graph.last.step == int(graph.status["step"]), timeout=60), plan
    assert graph.spin_until(lambda: all(p.poll() is not None for p in graph.procs.values()), timeout=120,
                            stop_on_failure=False), (plan, {n: p.poll() for n, p in graph.procs.items()})
    sim_log = graph.output("rod_simulator")
    assert "no couple for step" not in sim_log, (plan, sim_log[-3000:])  # no stall, no fallback
    print(next((line for line in sim_log.splitlines() if "the loop closed" in line), "step 0 answered at once"))
    _, session = paper_core
    assert graph.status["missed_deadlines"] == "0" and float(graph.status["settle_time_s"]) == session.settle_time, (
        plan, graph.status)
    assert graph.last is not None
    same_as_core(graph.last, paper_core)
    codes = graph.close()
    assert all(code == 0 for code in codes.values()), (plan, codes)


