"""Install the ROS 2 package resources of an *editable* checkout into the running environment.

``pip install .`` installs them from ``[tool.setuptools.data-files]`` in pyproject.toml, but
setuptools' editable installs skip data files; the project's set-up runs this module after
``pip install -e`` so that ``ros2 run contgrasp_ros <node>`` finds the ament index marker,
``share/contgrasp_ros/package.xml`` and the executables in ``lib/contgrasp_ros/``. It reads
the same table from pyproject.toml (no second list to keep in sync) and is idempotent.
"""

from __future__ import annotations

import shutil
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def install(prefix: Path = Path(sys.prefix)) -> list[Path]:
    """Copy every data file to ``prefix``; returns the installed paths."""
    table = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["data-files"]
    done = []
    for target_dir, sources in table.items():
        dest_dir = prefix / target_dir
        dest_dir.mkdir(parents=True, exist_ok=True)
        for src in sources:
            dest = dest_dir / Path(src).name
            shutil.copy2(ROOT / src, dest)  # keeps the executable bit of lib/ wrappers
            done.append(dest)
    return done


if __name__ == "__main__":
    for path in install():
        print(f"installed {path}")
