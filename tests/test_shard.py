"""CI's split of the heavy tests (tests/shard.py): the shards together run every test, each heavy
one in exactly one shard, the others in all, a file marked per module in one piece."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

import shard
from shard import deal, heavy_first, in_shard, pytest_collection_modifyitems, shard_from_env


@dataclass
class Item:
    """What the shard reads of a collected test: its id and its closest ``heavy`` mark."""

    nodeid: str
    mark: Any = None
    user_properties: list[tuple[str, Any]] = field(default_factory=list)

    def get_closest_marker(self, name: str) -> Any:
        return self.mark if name == "heavy" else None


@dataclass
class Config:
    deselected: list[Any] = field(default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)

    def getoption(self, name: str, default: Any = None) -> Any:
        return self.options.get(name, default)

    @property
    def hook(self) -> Any:
        return self

    def pytest_deselected(self, items: list[Any]) -> None:
        self.deselected += items


def items() -> list[Item]:
    light = [Item(f"tests/test_a.py::test_light_{i}") for i in range(5)]
    heavy = [Item(f"tests/test_a.py::test_heavy[{i}]", pytest.mark.heavy.mark) for i in range(40)]
    together = [Item(f"tests/test_b.py::test_together[{i}]", pytest.mark.heavy(per_module=True).mark) for i in range(6)]
    return light + heavy + together


@pytest.mark.parametrize("n", [1, 2, 3])
def test_the_shards_together_run_every_test_and_each_heavy_one_once(monkeypatch: pytest.MonkeyPatch, n: int) -> None:
    every = items()
    shards = []
    for k in range(1, n + 1):
        monkeypatch.setenv("CONTGRASP_TEST_SHARD", f"{k}/{n}")
        kept, config = items(), Config()
        pytest_collection_modifyitems(config, kept)  # type: ignore[arg-type]
        assert {i.nodeid for i in kept} | {i.nodeid for i in config.deselected} == {i.nodeid for i in every}
        shards.append({i.nodeid for i in kept})
    for test in every:
        runs = sum(test.nodeid in s for s in shards)
        assert runs == (n if test.mark is None else 1), test
    heavy_per_shard = [sum("test_heavy" in t for t in s) for s in shards]
    assert all(c > 0 for c in heavy_per_shard)  # (forty heavy tests are spread over every shard)
    assert sum(any("test_b.py" in t for t in s) for s in shards) == 1  # (a file marked per module stays in one piece)


def test_without_a_shard_every_test_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CONTGRASP_TEST_SHARD", raising=False)
    kept, config = items(), Config()
    pytest_collection_modifyitems(config, kept)  # type: ignore[arg-type]
    assert len(kept) == len(items()) and not config.deselected
    assert in_shard(Item("tests/test_x.py::test_light"), (2, 2))  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", ["0/2", "3/2", "a/b", "1"])
def test_a_malformed_shard_is_a_usage_error(monkeypatch: pytest.MonkeyPatch, bad: str) -> None:
    monkeypatch.setenv("CONTGRASP_TEST_SHARD", bad)
    with pytest.raises(pytest.UsageError, match=r"CONTGRASP_TEST_SHARD must be K/N with 1 <= K <= N"):
        shard_from_env()


def test_the_files_with_the_most_heavy_tests_go_first_each_in_its_own_order() -> None:
    heavy, per_module = pytest.mark.heavy.mark, pytest.mark.heavy(per_module=True).mark
    collected = [Item("tests/test_z.py::test_1"), Item("tests/test_z.py::test_2"),
                 Item("tests/test_x.py::test_1"), Item("tests/test_x.py::test_2", heavy), Item("tests/test_x.py::test_3"),
                 Item("tests/test_y.py::test_1", heavy), Item("tests/test_y.py::test_2", heavy),
                 Item("tests/test_w.py::test_1", per_module), Item("tests/test_w.py::test_2", per_module),
                 Item("tests/test_w.py::test_3", per_module)]
    order = [i.nodeid for i in heavy_first(collected)]  # type: ignore[arg-type]
    assert order == ["tests/test_w.py::test_1", "tests/test_w.py::test_2", "tests/test_w.py::test_3",
                     "tests/test_y.py::test_1", "tests/test_y.py::test_2",
                     "tests/test_x.py::test_1", "tests/test_x.py::test_2", "tests/test_x.py::test_3",
                     "tests/test_z.py::test_1", "tests/test_z.py::test_2"]


def test_the_longest_units_are_dealt_first_each_to_the_least_loaded_shard() -> None:
    durations = {"a": 5.0, "b": 4.0, "c": 3.0, "d": 3.0, "e": 3.0}
    assert deal(durations, 2) == {"a": 0, "b": 1, "c": 1, "d": 0, "e": 1}  # loads 8 and 10
    many = {f"t{i}": float((7 * i) % 23 + 1) for i in range(60)}
    for n in (2, 3):
        dealt = deal(many, n)
        loads = [sum(s for k, s in many.items() if dealt[k] == j) for j in range(n)]
        assert max(loads) - min(loads) <= max(many.values())  # (the deal's bound: one unit at most)


def test_a_heavy_test_goes_where_the_stored_deal_puts_it_a_new_one_where_its_hash_does() -> None:
    heavy = pytest.mark.heavy.mark
    dealt = {"tests/test_a.py::test_1": 1}
    stored = Item("tests/test_a.py::test_1", heavy)
    assert [in_shard(stored, (k, 2), dealt) for k in (1, 2)] == [False, True]  # type: ignore[arg-type]
    new = Item("tests/test_a.py::test_new", heavy)
    assert sum(in_shard(new, (k, 2), dealt) for k in (1, 2)) == 1  # type: ignore[arg-type]
    assert in_shard(new, (1, 2), dealt) == in_shard(new, (1, 2), {})  # type: ignore[arg-type]


def test_the_stored_durations_deal_the_collected_heavy_tests() -> None:
    """tests/heavy_durations.json names only heavy tests that exist (a renamed one would be dealt
    by its hash), with durations of two seconds and more, split about evenly by the deal."""
    import json

    stored = json.loads(shard.DURATIONS.read_text())
    assert stored and all(isinstance(s, float) and s >= 0 for s in stored.values())
    dealt = deal(stored, 2)
    loads = [sum(s for k, s in stored.items() if dealt[k] == j) for j in range(2)]
    assert abs(loads[0] - loads[1]) <= max(stored.values())


def test_the_durations_of_a_run_are_stored_per_unit(tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CONTGRASP_TEST_SHARD", raising=False)
    monkeypatch.setattr(shard, "_measured", shard.Counter())
    collected, config = items(), Config()
    pytest_collection_modifyitems(config, collected)  # type: ignore[arg-type]
    for item in collected:
        for phase in ("setup", "call", "teardown"):
            shard.pytest_runtest_logreport(pytest.TestReport(item.nodeid, ("", 0, ""), {}, "passed", None, phase,
                                                             user_properties=item.user_properties, duration=0.25))
    out = tmp_path / "durations.json"

    class Session:
        config = Config(options={"--store-heavy-durations": str(out)})

    shard.store_durations(Session())  # type: ignore[arg-type]
    stored = __import__("json").loads(out.read_text())
    assert stored == {**{f"tests/test_a.py::test_heavy[{i}]": 0.8 for i in range(40)}, "tests/test_b.py": 4.5}


def test_storing_durations_in_a_shard_is_a_usage_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONTGRASP_TEST_SHARD", "1/2")
    with pytest.raises(pytest.UsageError, match="measures every test"):
        pytest_collection_modifyitems(Config(options={"--store-heavy-durations": "x"}), items())  # type: ignore[arg-type]
