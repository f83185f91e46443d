"""CI's split of the heavy tests (tests/shard.py): the shards together run every test, the heavy
ones in exactly one shard, the others in all, a file marked per module in one piece."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

FILES = {
    "test_a.py": """
import pytest

def test_light():
    pass

@pytest.mark.heavy
@pytest.mark.parametrize("i", range(12))
def test_heavy(i):
    pass
""",
    "test_b.py": """
import pytest

pytestmark = pytest.mark.heavy(per_module=True)

@pytest.mark.parametrize("i", range(12))
def test_together(i):
    pass
""",
}


def collected(tmp_path: Path, shard: str | None) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "CONTGRASP_TEST_SHARD"}
    env["PYTHONPATH"] = os.pathsep.join([str(TESTS), env.get("PYTHONPATH", "")])
    if shard is not None:
        env["CONTGRASP_TEST_SHARD"] = shard
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "shard", "-p", "no:cacheprovider", "--collect-only", "-q",
                           "-o", "markers=heavy", "--rootdir", str(tmp_path), str(tmp_path)],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)


def ids(proc: subprocess.CompletedProcess[str]) -> set[str]:
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {line for line in proc.stdout.splitlines() if "::" in line}


@pytest.mark.parametrize("n", [2, 3])
def test_the_shards_together_run_every_test_and_each_heavy_one_once(tmp_path: Path, n: int) -> None:
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    every = ids(collected(tmp_path, None))
    assert len(every) == 25
    shards = [ids(collected(tmp_path, f"{k}/{n}")) for k in range(1, n + 1)]
    assert set().union(*shards) == every
    for test in every:
        runs = sum(test in s for s in shards)
        assert runs == (n if test.endswith("test_light") else 1), test
    assert sum(any("test_heavy" in t for t in s) for s in shards) >= 2  # (twelve heavy tests are spread out)
    assert sum(any("test_b.py" in t for t in s) for s in shards) == 1  # (a file marked per module stays in one piece)


@pytest.mark.parametrize("bad", ["0/2", "3/2", "a/b"])
def test_a_malformed_shard_is_a_usage_error(tmp_path: Path, bad: str) -> None:
    (tmp_path / "test_a.py").write_text(FILES["test_a.py"])
    proc = collected(tmp_path, bad)
    assert proc.returncode == 4 and "CONTGRASP_TEST_SHARD must be K/N with 1 <= K <= N" in proc.stderr, proc.stderr
