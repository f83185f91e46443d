"""The heavy tests' place in a run (a pytest plugin; tests/conftest.py loads its hook): with
``CONTGRASP_TEST_SHARD=K/N`` (CI: one shard per interpreter) a test marked ``heavy`` runs in shard
K only, every other test in every shard; and the files with the most heavy tests go first, so
that two workers do not end on one long file (docs/install.md)."""

from __future__ import annotations

import os
import re
import zlib
from collections import Counter

import pytest


def shard_from_env() -> tuple[int, int] | None:
    """``CONTGRASP_TEST_SHARD=K/N`` (CI: one value per interpreter), or None (every test)."""
    value = os.environ.get("CONTGRASP_TEST_SHARD", "")
    if not value:
        return None
    m = re.fullmatch(r"(\d+)/(\d+)", value)
    if m is None or not 1 <= int(m.group(1)) <= int(m.group(2)):
        raise pytest.UsageError(f"CONTGRASP_TEST_SHARD must be K/N with 1 <= K <= N, got {value!r}")
    return int(m.group(1)), int(m.group(2))


def in_shard(item: pytest.Item, shard: tuple[int, int]) -> bool:
    """Whether ``item`` runs in ``shard`` = (K, N): a test not marked ``heavy`` always; a heavy one
    when a fixed hash of its id (of its file, for ``heavy(per_module=True)``: a file whose tests
    share one costly fixture) is K - 1 modulo N, the same whatever else was collected."""
    mark = item.get_closest_marker("heavy")
    if mark is None:
        return True
    key = item.nodeid.split("::")[0] if mark.kwargs.get("per_module") else item.nodeid
    return zlib.crc32(key.encode()) % shard[1] == shard[0] - 1


def heavy_first(items: list[pytest.Item]) -> list[pytest.Item]:
    """``items`` with the files holding the most heavy tests first, each file's own order kept
    (the longest jobs first: pytest-xdist then hands out whole files in this order, with
    ``--no-loadscope-reorder``; a file marked per module counts each of its tests as heavy)."""
    heavy = Counter(item.nodeid.split("::")[0] for item in items if item.get_closest_marker("heavy") is not None)
    return sorted(items, key=lambda item: -heavy[item.nodeid.split("::")[0]])


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Keep the tests of this run's shard (:func:`shard_from_env`, :func:`in_shard`), heaviest
    files first (:func:`heavy_first`)."""
    shard = shard_from_env()
    if shard is not None:
        keep: list[pytest.Item] = []
        drop: list[pytest.Item] = []
        for item in items:
            (keep if in_shard(item, shard) else drop).append(item)
        if drop:
            config.hook.pytest_deselected(items=drop)
        items[:] = keep
    items[:] = heavy_first(items)
