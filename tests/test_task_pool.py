"""The ``processes`` executor of contgrasp_core.executors: results in the items' order, a failed
task's exception in the parent, a worker that dies reported instead of waited for, and no worker
left when the consumer stops early (the Ctrl-C path: tests/test_holding_study.py)."""

from __future__ import annotations

import multiprocessing as mp
import os
import time

import pytest

from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.executors import run_tasks


def _square_slowly(x: int) -> int:
    time.sleep(0.002 * (x % 4))  # answers arrive out of order
    return x * x


def _fails_at_five(x: int) -> int:
    if x == 5:
        raise ValueError("five")
    return x


def _dies_at_three(x: int) -> int:
    if x == 3:
        os._exit(7)
    return x


def _pid(_: int) -> int:
    time.sleep(0.01)
    return os.getpid()


@pytest.mark.parametrize("workers", [1, 2, 5])
def test_results_come_in_the_items_order_as_serially(workers: int) -> None:
    items = list(range(23))
    assert list(run_tasks(_square_slowly, items, "processes", workers=workers)) == [x * x for x in items]
    assert list(run_tasks(_square_slowly, [], "processes", workers=workers)) == []


def test_the_work_is_shared_by_the_workers_asked_for() -> None:
    pids = set(run_tasks(_pid, list(range(20)), "processes", workers=2))
    assert len(pids) == 2 and os.getpid() not in pids


def test_a_failed_task_raises_its_exception_in_the_parent_and_ends_the_workers() -> None:
    with pytest.raises(ValueError, match="five"):
        list(run_tasks(_fails_at_five, list(range(40)), "processes", workers=2))
    assert mp.active_children() == []


def test_a_worker_that_dies_is_reported_not_waited_for() -> None:
    with pytest.raises(RuntimeError, match="exit code 7"):
        list(run_tasks(_dies_at_three, list(range(10)), "processes", workers=2))
    assert mp.active_children() == []


def test_a_consumer_that_stops_early_leaves_no_worker() -> None:
    results = run_tasks(_square_slowly, list(range(200)), "processes", workers=2)
    assert next(results) == 0
    results.close()
    assert mp.active_children() == []


def test_unknown_executor_is_refused() -> None:
    with pytest.raises(InvalidParameterError, match="unknown executor"):
        list(run_tasks(_square_slowly, [1], "threads"))
