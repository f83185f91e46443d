"""CI's split of the heavy tests between its interpreters (a pytest plugin; tests/conftest.py
loads its hook): with ``CONTGRASP_TEST_SHARD=K/N`` a test marked ``heavy`` runs in shard K only,
every other test in every shard; without it every test runs (docs/install.md)."""

from __future__ import annotations

import os
import re
import zlib

import pytest


def _shard() -> tuple[int, int] | None:
    """``CONTGRASP_TEST_SHARD=K/N`` (CI: one value per interpreter), or None (every test)."""
    value = os.environ.get("CONTGRASP_TEST_SHARD", "")
    if not value:
        return None
    m = re.fullmatch(r"(\d+)/(\d+)", value)
    if m is None or not 1 <= int(m.group(1)) <= int(m.group(2)):
        raise pytest.UsageError(f"CONTGRASP_TEST_SHARD must be K/N with 1 <= K <= N, got {value!r}")
    return int(m.group(1)), int(m.group(2))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """With ``CONTGRASP_TEST_SHARD=K/N`` keep the ``heavy`` tests of shard K only (every other test
    runs in every shard). A test's shard is a fixed hash of its id, or of its file for
    ``heavy(per_module=True)`` (a module whose tests share one costly fixture), so it is the same
    whatever else was collected: the N shards together run every test at least once."""
    shard = _shard()
    if shard is None:
        return
    k, n = shard
    keep, drop = [], []
    for item in items:
        mark = item.get_closest_marker("heavy")
        key = item.nodeid.split("::")[0] if mark is not None and mark.kwargs.get("per_module") else item.nodeid
        (drop if mark is not None and zlib.crc32(key.encode()) % n != k - 1 else keep).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep
