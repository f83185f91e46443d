"""Build and install the contgrasp_msgs interface package into the running virtual environment.

Run with the venv's interpreter (``.venv/bin/python msgs_schema/build_into_venv.py``); the
project's set-up does it: point the ROS wheels' exported CMake files at this interpreter's
include directories, then a plain ``cmake`` configure / build / install into the venv, then
import the generated messages in a fresh interpreter. A stamp of the interface sources makes a
second run a no-op; the build folder is ``<venv>/build/contgrasp_msgs``. The package stays
buildable with ``colcon build``. docs/design.md, section 1.
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy

HERE = Path(__file__).resolve().parent
PREFIX = Path(sys.prefix)
# the wheel builder's interpreter prefix (manylinux's /opt/python/<tag>) and, under it, the
# numpy include directory (numpy/_core/include since numpy 2, numpy/core/include before)
WHEEL_PYTHON = r"/opt/python/cp3\d+-cp3\d+t?"
WHEEL_NUMPY_INCLUDE = re.compile(WHEEL_PYTHON + r"/lib/python3\.\d+t?/site-packages/numpy/_?core/include")
WHEEL_PY_INCLUDE = re.compile(WHEEL_PYTHON + r"/include/python3\.\d+t?")


def source_hash() -> str:
    h = hashlib.sha256()
    for path in sorted([HERE / "CMakeLists.txt", HERE / "package.xml", *HERE.glob("msg/*.msg"), *HERE.glob("srv/*.srv")]):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def fix_wheel_cmake_paths() -> int:
    py_inc = sysconfig.get_paths()["include"]
    np_inc = numpy.get_include()
    fixed = 0
    for path in (PREFIX / "share").rglob("*.cmake"):
        text = path.read_text(errors="surrogateescape")
        new = WHEEL_PY_INCLUDE.sub(lambda _: py_inc, WHEEL_NUMPY_INCLUDE.sub(lambda _: np_inc, text))
        if new != text:
            path.write_text(new, errors="surrogateescape")
            fixed += 1
    return fixed


def run(cmd: list[str], **kw: object) -> None:
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, **kw)  # type: ignore[call-overload]


def main() -> int:
    stamp = PREFIX / ".contgrasp-msgs"
    want = source_hash()
    if stamp.exists() and stamp.read_text() == want and import_ok():
        print("contgrasp_msgs: up to date")
        return 0
    n = fix_wheel_cmake_paths()
    print(f"contgrasp_msgs: corrected {n} wheel CMake files")
    build = PREFIX / "build" / "contgrasp_msgs"
    build.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PATH=f"{PREFIX / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    run(
        [
            "cmake",
            "-S", str(HERE),
            "-B", str(build),
            f"-DCMAKE_INSTALL_PREFIX={PREFIX}",
            f"-DCMAKE_PREFIX_PATH={PREFIX}",
            f"-DPython3_EXECUTABLE={sys.executable}",
            "-DBUILD_TESTING=OFF",
            "-DCMAKE_BUILD_TYPE=Release",
        ],
        env=env,
        stdout=subprocess.DEVNULL,
    )
    run(["cmake", "--build", str(build), "-j", str(os.cpu_count() or 2)], env=env, stdout=subprocess.DEVNULL)
    run(["cmake", "--install", str(build)], env=env, stdout=subprocess.DEVNULL)
    if not import_ok():
        print("contgrasp_msgs: built but the Python messages do not import", file=sys.stderr)
        return 1
    stamp.write_text(want)
    print("contgrasp_msgs: installed into", PREFIX)
    return 0


def import_ok() -> bool:
    code = ("from contgrasp_msgs.msg import RodState, ContactState, CoupleControl, GraspQuality, ObjectBoundary; "
            "from contgrasp_msgs.srv import ApplyWrench")
    return subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0


if __name__ == "__main__":
    sys.exit(main())
