"""The heavy tests' place in a run (a pytest plugin; tests/conftest.py loads its hooks): with
``CONTGRASP_TEST_SHARD=K/N`` (CI: one shard per interpreter) a test marked ``heavy`` runs in shard
K only, every other test in every shard, the heavy ones dealt out by their measured durations
(``tests/heavy_durations.json``, written by ``--store-heavy-durations``) so that the shards take
as long; and the files with the most heavy tests go first, so that two workers do not end on one
long file (docs/install.md)."""

from __future__ import annotations

import json
import os
import re
import zlib
from collections import Counter
from functools import cache
from pathlib import Path

import pytest

DURATIONS = Path(__file__).with_name("heavy_durations.json")


def shard_from_env() -> tuple[int, int] | None:
    """``CONTGRASP_TEST_SHARD=K/N`` (CI: one value per interpreter), or None (every test)."""
    value = os.environ.get("CONTGRASP_TEST_SHARD", "")
    if not value:
        return None
    m = re.fullmatch(r"(\d+)/(\d+)", value)
    if m is None or not 1 <= int(m.group(1)) <= int(m.group(2)):
        raise pytest.UsageError(f"CONTGRASP_TEST_SHARD must be K/N with 1 <= K <= N, got {value!r}")
    return int(m.group(1)), int(m.group(2))


def unit(item: pytest.Item) -> str | None:
    """What is dealt to one shard: a heavy test's id (its file's, for ``heavy(per_module=True)``:
    a file whose tests share one costly fixture); None for a test not marked ``heavy``."""
    mark = item.get_closest_marker("heavy")
    if mark is None:
        return None
    return item.nodeid.split("::")[0] if mark.kwargs.get("per_module") else item.nodeid


def deal(durations: dict[str, float], n: int) -> dict[str, int]:
    """The shard (0 to n - 1) of each unit: the longest first, each to the shard with the least
    time so far (longest-processing-time first; ties by id, so every interpreter deals alike)."""
    load = [0.0] * n
    dealt: dict[str, int] = {}
    for key, seconds in sorted(durations.items(), key=lambda kv: (-kv[1], kv[0])):
        dealt[key] = k = load.index(min(load))
        load[k] += seconds
    return dealt


@cache
def stored_deal(n: int) -> dict[str, int]:
    """:func:`deal` of the durations stored in ``tests/heavy_durations.json`` (none: empty)."""
    return deal(json.loads(DURATIONS.read_text()) if DURATIONS.exists() else {}, n)


def in_shard(item: pytest.Item, shard: tuple[int, int], dealt: dict[str, int] | None = None) -> bool:
    """Whether ``item`` runs in ``shard`` = (K, N): a test not marked ``heavy`` always; a heavy one
    where ``dealt`` (by default :func:`stored_deal`) puts its unit, and a unit measured since (a
    new test) where a fixed hash of it, modulo N, puts it: the same whatever else was collected."""
    key = unit(item)
    if key is None:
        return True
    dealt = stored_deal(shard[1]) if dealt is None else dealt
    k = dealt[key] if key in dealt else zlib.crc32(key.encode()) % shard[1]
    return k == shard[0] - 1


def heavy_first(items: list[pytest.Item]) -> list[pytest.Item]:
    """``items`` with the files holding the most heavy tests first, each file's own order kept
    (the longest jobs first: pytest-xdist then hands out whole files in this order, with
    ``--no-loadscope-reorder``; a file marked per module counts each of its tests as heavy)."""
    heavy = Counter(item.nodeid.split("::")[0] for item in items if item.get_closest_marker("heavy") is not None)
    return sorted(items, key=lambda item: -heavy[item.nodeid.split("::")[0]])


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Keep the tests of this run's shard (:func:`shard_from_env`, :func:`in_shard`), heaviest
    files first (:func:`heavy_first`); each heavy test carries its unit (``heavy_unit``)."""
    for item in items:
        if (key := unit(item)) is not None:
            item.user_properties.append(("heavy_unit", key))
    shard = shard_from_env()
    if shard is not None and config.getoption("--store-heavy-durations", None):
        raise pytest.UsageError("--store-heavy-durations measures every test: unset CONTGRASP_TEST_SHARD")
    if shard is not None:
        keep: list[pytest.Item] = []
        drop: list[pytest.Item] = []
        for item in items:
            (keep if in_shard(item, shard) else drop).append(item)
        if drop:
            config.hook.pytest_deselected(items=drop)
        items[:] = keep
    items[:] = heavy_first(items)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--store-heavy-durations", metavar="PATH",
                     help="write the heavy tests' durations to PATH (a run of every test; CI deals out "
                          "tests/heavy_durations.json)")


_measured: Counter[str] = Counter()


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Add a heavy test's set-up, call and teardown to its unit's time (the unit travels with the
    report, from a pytest-xdist worker too: :func:`pytest_collection_modifyitems`)."""
    key = dict(report.user_properties).get("heavy_unit")
    if key is not None:
        _measured[key] += report.duration


def store_durations(session: pytest.Session) -> None:
    """With ``--store-heavy-durations PATH``: store what the whole run measured (its main process)."""
    path = session.config.getoption("--store-heavy-durations")
    if path and not hasattr(session.config, "workerinput"):
        Path(path).write_text(json.dumps({k: round(v, 1) for k, v in sorted(_measured.items())}, indent=1) + "\n")
