"""The figure package draws with matplotlib's object API and never touches the backend."""

from __future__ import annotations

import subprocess
import sys


def test_importing_and_drawing_figures_keeps_the_users_backend(tmp_path) -> None:
    """A notebook's backend survives importing every figure module and saving a figure."""
    code = f"""
import matplotlib
matplotlib.use("svg")
import contgrasp_core.figures.closed_loop, contgrasp_core.figures.grasp, contgrasp_core.figures.quality_map
from contgrasp_core.figures.draw import draw_boundary, save
from contgrasp_core.boundary import circle
from matplotlib.figure import Figure
fig = Figure()
draw_boundary(fig.subplots(), circle(1.0))
save(fig, {str(tmp_path / 'c.png')!r})
print(matplotlib.get_backend())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "svg"
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
