"""The repository's text reads without a tracker and its modules open briefly.

A reader has no issue tracker, so no tracked text cites one; a module's docstring says what the
module is for in a few lines, and the mechanisms and measurements live in docs/.
"""

from __future__ import annotations

import ast
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXT_SUFFIXES = (".py", ".md", ".toml", ".yaml", ".xml", ".sh", ".cfg", ".txt")
# the word, optionally plural, then a number (optionally after '#') or a quoted name; built in two
# parts so that this file does not match itself
TRACKER = re.compile("[Ii]ssue" + r"""s?\s*(#?\d+|")""")
DOCSTRING_DIRS = ("contgrasp_core", "contgrasp_ros", "benchmarks")
MAX_DOCSTRING_LINES = 15


def _tracked(*patterns: str) -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--", *patterns], cwd=ROOT, capture_output=True,
                             text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [name for name in out.split("\0") if name and (ROOT / name).is_file()]


def test_no_tracked_text_cites_a_tracker_number() -> None:
    found = []
    for name in _tracked(*(f"*{suffix}" for suffix in TEXT_SUFFIXES)):
        text = (ROOT / name).read_text(encoding="utf-8", errors="replace")
        for number, line in enumerate(text.splitlines(), 1):
            if TRACKER.search(line):
                found.append(f"{name}:{number}: {line.strip()[:100]}")
    assert not found, "tracker references (say what instead):\n" + "\n".join(found)


def test_module_docstrings_are_short() -> None:
    long = []
    for name in _tracked(*(f"{folder}/*.py" for folder in DOCSTRING_DIRS)):
        doc = ast.get_docstring(ast.parse((ROOT / name).read_text(encoding="utf-8")), clean=False)
        lines = len(doc.split("\n")) if doc else 0
        if lines > MAX_DOCSTRING_LINES:
            long.append(f"{name}: {lines} lines")
    assert not long, (f"module docstrings longer than {MAX_DOCSTRING_LINES} lines (move the detail to "
                      "docs/):\n" + "\n".join(long))
