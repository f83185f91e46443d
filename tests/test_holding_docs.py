"""The scripts behind docs/holding.md's tables still run and give the tables' numbers."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs" / "holding"


@pytest.mark.heavy
def test_the_ceiling_table_prints_the_documented_ceiling() -> None:
    out = subprocess.run([sys.executable, str(DOCS / "ceiling_table.py")], capture_output=True, text=True, check=True,
                         timeout=600).stdout
    assert "100000 Pa  mu 0.5: holds the shape True, min 0.046 N" in out
    assert "50000 Pa  mu 0.0: holds the shape False, min 0.000 N" in out
    assert "the 50 kPa plan's rest: the clamp's bend leaves 3.4% of its muscle, the other joints at least 76%" in out
    for mu in (0.5, 1.0, 2.0):  # (the clamp binds +x, 270 and 315 degrees whatever the friction)
        assert f"50000 Pa  mu {mu}: the 50 kPa plan's rest, holds the shape True, min 0.010 N, [0.015 " in out, out


@pytest.mark.heavy
def test_the_shape_search_prints_the_documented_best_wrap() -> None:
    out = subprocess.run([sys.executable, str(DOCS / "shape_search.py"), "--no-refine", "--nominal"], capture_output=True, text=True,
                         check=True, timeout=600).stdout
    assert "291 designed wraps clear of the circle; 150 held by their muscles" in out, out
    assert "best designed wrap: weakest 0.0299 N (direction 9), its binding joint 78 at s = 0.156 m, r = 3.0 mm" in out, out
    assert "mu 0.5: weakest at 50, 100, 200, 400 kPa: 0.030, 0.061, 0.122, 0.245 N; 0.24 N at 392 kPa" in out, out
    assert "mu 1.0: weakest at 50, 100, 200, 400 kPa: 0.062, 0.125, 0.252, 0.506 N; 0.24 N at 190 kPa" in out, out


def test_the_object_set_script_refuses_what_cannot_be_wrapped() -> None:
    spec = importlib.util.spec_from_file_location("object_set", DOCS / "object_set.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    name, mu, text = module.run("circle 35 mm", 0.0)
    assert (name, mu) == ("circle 35 mm", 0.0) and text.startswith("refused: the holding law cannot close")


@pytest.mark.heavy
def test_the_object_set_script_refuses_nonsense_options_in_one_line() -> None:
    for bad in (["--workers", "0"], ["--max-muscle-stress", "-1"], ["--max-muscle-stress", "nan"]):
        proc = subprocess.run([sys.executable, str(DOCS / "object_set.py"), *bad], capture_output=True, text=True,
                              timeout=120)
        assert proc.returncode == 2 and proc.stderr.strip().splitlines()[-1].startswith("object_set.py: error:")
