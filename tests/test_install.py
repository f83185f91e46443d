"""The library alone (docs/install.md, "The library alone"): ``pip install`` of this repository
with no extras, in a fresh virtual environment of the running interpreter, installs nothing from
ROS, no mcap and no foxglove; the core subcommands run; the ROS layer's commands say in one line
what to install.

This is what a researcher on macOS, Windows or aarch64 gets: the wheel is ``py3-none-any``, so it
installs wherever numpy, scipy and numba do. It builds the wheel from the checkout's files and
installs its dependencies from the package index (pip's cache makes a second run quick).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "bags" / "paper_grasp.mcap"


def _checkout_files() -> list[str]:
    """The repository's files as a clone has them (tracked, plus new files not ignored)."""
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                         capture_output=True, check=True).stdout
    return [name for name in out.decode().split("\0") if name and (ROOT / name).is_file()]


def _clean_env(home: Path) -> dict[str, str]:
    """An environment with nothing of this project's venv or of a ROS install in it."""
    keep = {k: v for k, v in os.environ.items() if k in ("PATH", "LANG", "LC_ALL", "TMPDIR", "PIP_INDEX_URL",
                                                          "PIP_EXTRA_INDEX_URL", "PIP_FIND_LINKS", "PIP_CONFIG_FILE")}
    keep["PATH"] = os.pathsep.join(p for p in keep.get("PATH", "").split(os.pathsep) if not p.startswith(sys.prefix))
    return dict(keep, HOME=str(home), MPLBACKEND="Agg", PIP_DISABLE_PIP_VERSION_CHECK="1",
                XDG_CACHE_HOME=os.environ.get("XDG_CACHE_HOME", str(Path.home() / ".cache")))


@pytest.fixture(scope="module")
def library(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """A fresh venv with the wheel built from this checkout installed, no extras."""
    tmp = tmp_path_factory.mktemp("library")
    src = tmp / "src"
    for name in _checkout_files():
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, src / name)
    env = _clean_env(tmp)
    wheels = tmp / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", str(src), "-w", str(wheels)],
                   check=True, env=env, capture_output=True, text=True)
    (wheel,) = wheels.glob("*.whl")
    env_dir = tmp / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    bin_dir = env_dir / ("Scripts" if os.name == "nt" else "bin")
    # (--no-compile: what is installed is the same; only the byte code of the ~4,000 modules of
    # numpy, scipy, matplotlib and numba is left to be written at first import, for the few the
    # commands below import: ~10 CPU-s less)
    installed = subprocess.run([str(bin_dir / "python"), "-m", "pip", "install", "--quiet", "--no-compile", str(wheel)],
                               env=env, capture_output=True, text=True)
    assert installed.returncode == 0, installed.stderr
    return {"wheel": wheel, "bin": bin_dir, "env": env, "cwd": tmp}


def _run(library: dict[str, object], *argv: str) -> subprocess.CompletedProcess[str]:
    bin_dir = library["bin"]
    assert isinstance(bin_dir, Path)
    return subprocess.run([str(bin_dir / argv[0]), *argv[1:]], capture_output=True, text=True, timeout=600,
                          env=library["env"], cwd=library["cwd"])  # type: ignore[arg-type]


def test_the_wheel_is_platform_independent(library: dict[str, object]) -> None:
    wheel = library["wheel"]
    assert isinstance(wheel, Path)
    assert wheel.name.endswith("-py3-none-any.whl"), wheel.name


def test_nothing_from_ros_mcap_or_foxglove_is_installed(library: dict[str, object]) -> None:
    listed = _run(library, "python", "-m", "pip", "list", "--format", "json")
    names = {p["name"].lower() for p in json.loads(listed.stdout)}
    assert "contgrasp" in names and {"numpy", "scipy", "numba", "matplotlib"} <= names
    assert not [n for n in names if n.startswith(("ros-", "ros_", "mcap", "foxglove", "rclpy"))], sorted(names)
    assert _run(library, "python", "-c", "import rclpy").returncode != 0


def test_the_core_subcommands_run(library: dict[str, object]) -> None:
    grasp = _run(library, "contgrasp", "grasp", "--json")
    assert grasp.returncode == 0, grasp.stderr
    assert json.loads(grasp.stdout)["converged"] is True
    qmap = _run(library, "contgrasp", "quality-map", "--psi-steps", "4", "--d-steps", "2", "--nodes", "60",
                "--executor", "serial", "--json")
    assert qmap.returncode == 0, qmap.stderr
    assert json.loads(qmap.stdout)
    sim = _run(library, "contgrasp", "simulate", "--duration", "0.2", "--json")
    assert sim.returncode == 0, sim.stderr
    assert json.loads(sim.stdout)["sim_time_s"] == pytest.approx(0.2)
    same = _run(library, "python", "-m", "contgrasp_core.cli", "--version")
    assert same.returncode == 0 and same.stdout.startswith("contgrasp ")


@pytest.mark.parametrize("argv", [["contgrasp", "analyze", "x.mcap"], ["contgrasp", "bag", "info", str(BAG)],
                                  ["contgrasp-launch", "--no-record"], ["contgrasp-simulator"],
                                  ["../lib/contgrasp_ros/rod_simulator"]])  # (the last: what `ros2 run` runs)
def test_a_ros_command_says_what_to_install(library: dict[str, object], argv: list[str]) -> None:
    out = _run(library, *argv)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert "pip install 'contgrasp[ros" in lines[0], lines[0]
