"""The paper map (docs/paper_map.md) and the module table of docs/design.md name only things that exist.

The map says which function implements which numbered equation and which test checks it; these
tests import every function it names and find every test it names, and require every numbered
equation of the paper to be either mapped or listed as not implemented. The module table
(docs/design.md, "Every module") must name every module and package of ``contgrasp_core`` and
``contgrasp_ros`` exactly once and nothing that does not exist; the links of README.md and
docs/install.md must lead to files that exist.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAPER_MAP = ROOT / "docs" / "paper_map.md"
README = ROOT / "README.md"
DESIGN = ROOT / "docs" / "design.md"

# The paper's numbered equations as printed (derivation in docs/paper_map.md): (1)-(21) in the
# body, (A-1) and in the appendices.
NUMBERED_EQUATIONS = {str(n) for n in range(1, 22)} | {"A-1", "A-2"}

FUNCTION = re.compile(r"`([A-Za-z_][\w]*(?:\.[A-Za-z_]\w*)+)`")
TEST = re.compile(r"`(tests/[\w/]+\.py)::(\w+)`")
EQUATION = re.compile(r"eq\. \(([0-9A-]+)\)")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def markdown_tables(text: str) -> list[tuple[list[str], list[list[str]]]]:
    """Every pipe table of ``text`` as (header cells, data rows)."""
    tables: list[tuple[list[str], list[list[str]]]] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines) - 1:
        if lines[i].lstrip().startswith("|") and re.fullmatch(r"\s*\|?(\s*:?-+:?\s*\|)+\s*:?-*:?\s*\|?\s*", lines[i + 1]):
            header = _cells(lines[i])
            rows = []
            i += 2
            while i < len(lines) and lines[i].lstrip().startswith("|"):
                rows.append(_cells(lines[i]))
                i += 1
            tables.append((header, rows))
        else:
            i += 1
    return tables


def _table(text: str, *columns: str) -> tuple[list[str], list[list[str]]]:
    found = [t for t in markdown_tables(text) if all(c in t[0] for c in columns)]
    assert len(found) == 1, f"expected one table with columns {columns}, found {len(found)}"
    return found[0]


def map_rows() -> list[dict[str, str]]:
    header, rows = _table(PAPER_MAP.read_text(encoding="utf-8"), "Paper", "Implemented by", "Checked by")
    for row in rows:
        assert len(row) == len(header), row
    return [dict(zip(header, row, strict=True)) for row in rows]


def resolve(name: str) -> object:
    """Import the longest module prefix of the dotted ``name`` and getattr the rest."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)  # AttributeError: the map names something that is gone
        return obj
    raise ModuleNotFoundError(name)


def defined_functions(path: Path) -> set[str]:
    """Names of the test functions defined in ``path`` (module level or in classes)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)}


def test_every_row_names_an_implementation_and_a_test() -> None:
    rows = map_rows()
    assert len(rows) > 20
    for row in rows:
        assert FUNCTION.findall(row["Implemented by"]), row
        assert TEST.findall(row["Checked by"]), row


def test_every_function_in_the_map_exists() -> None:
    names = sorted({n for row in map_rows() for n in FUNCTION.findall(row["Implemented by"])})
    missing = []
    for name in names:
        try:
            obj = resolve(name)
        except (ImportError, AttributeError) as exc:
            missing.append(f"{name}: {exc}")
            continue
        assert callable(obj), name
    assert not missing, "docs/paper_map.md names functions that do not exist:\n" + "\n".join(missing)


def test_every_test_in_the_map_exists() -> None:
    defined: dict[str, set[str]] = {}
    missing = []
    for row in map_rows():
        for file, name in TEST.findall(row["Checked by"]):
            path = ROOT / file
            if not path.is_file():
                missing.append(f"{file} (no such file)")
                continue
            if file not in defined:
                defined[file] = defined_functions(path)
            if not name.startswith("test_") or name not in defined[file]:
                missing.append(f"{file}::{name}")
    assert not missing, "docs/paper_map.md names tests that do not exist:\n" + "\n".join(missing)


def test_every_numbered_equation_is_mapped_or_listed_as_not_implemented() -> None:
    text = PAPER_MAP.read_text(encoding="utf-8")
    mapped = {e for row in map_rows() for e in EQUATION.findall(row["Paper"])}
    _, rows = _table(text, "Paper", "Why not")
    not_implemented = {e for row in rows for e in EQUATION.findall(row[0])}
    assert mapped <= NUMBERED_EQUATIONS, mapped - NUMBERED_EQUATIONS
    assert not_implemented <= NUMBERED_EQUATIONS, not_implemented - NUMBERED_EQUATIONS
    assert not mapped & not_implemented, mapped & not_implemented
    assert mapped | not_implemented == NUMBERED_EQUATIONS, NUMBERED_EQUATIONS - mapped - not_implemented


# ----------------------------------------------------------------------------- module table


def table_modules() -> list[str]:
    """The names in the first column of the module table (docs/design.md, ``Every module``)."""
    _, rows = _table(DESIGN.read_text(encoding="utf-8"), "module", "paper", "holds")
    names = []
    for row in rows:
        cell = re.findall(r"`([^`]+)`", row[0])
        assert cell, f"design.md module table row without a module name: {row}"
        names.extend(cell)
    return names


def existing_entries(package: str) -> set[str]:
    """Every module, package and data folder directly inside ``package`` (private ``_x`` modules
    and ``__init__``/``__pycache__`` excluded) as the module table names them: ``pkg.mod`` or ``pkg/dir/``."""
    out = set()
    for p in (ROOT / package).iterdir():
        if p.name.startswith("_"):
            continue
        if p.is_file() and p.suffix == ".py":
            out.add(f"{package}.{p.stem}")
        elif p.is_dir():
            out.add(f"{package}.{p.name}" if (p / "__init__.py").is_file() else f"{package}/{p.name}/")
    return out


def exists(name: str) -> bool:
    if name.endswith("/"):
        return (ROOT / name).is_dir()
    path = ROOT / name.replace(".", "/")
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def test_module_table_names_only_what_exists_and_each_once() -> None:
    names = table_modules()
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
    assert [n for n in names if not exists(n)] == []


@pytest.mark.parametrize("package", ["contgrasp_core", "contgrasp_ros"])
def test_module_table_covers_every_module(package: str) -> None:
    listed = set(table_modules())
    assert package in listed
    assert sorted(existing_entries(package) - listed) == []


def test_readme_and_design_link_the_paper_map() -> None:
    assert "docs/paper_map.md" in README.read_text(encoding="utf-8")
    assert "paper_map.md" in DESIGN.read_text(encoding="utf-8")


LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("page", ["README.md", "docs/install.md", "docs/design.md"])
def test_the_newcomers_pages_link_only_files_that_exist(page: str) -> None:
    """README.md sends a reader on by links (install, the docs, the figures): each must lead somewhere."""
    path = ROOT / page
    targets = [t.split("#")[0] for t in LINK.findall(path.read_text(encoding="utf-8"))]
    targets = [t for t in targets if t and "://" not in t]
    assert targets
    assert [t for t in targets if not (path.parent / t).exists()] == []


def test_the_readme_links_every_doc() -> None:
    """Depth lives in docs/, reached from README.md: every page of docs/ is linked from it."""
    text = README.read_text(encoding="utf-8")
    assert [p.name for p in sorted((ROOT / "docs").glob("*.md")) if f"docs/{p.name}" not in text] == []
    assert "benchmarks/RESULTS.md" in text
