#!/usr/bin/env bash
# contgrasp developer entry point: set everything up, then run the main job or the tests.
#
#   bash contgrasp.sh run    # set up (idempotent) and run the main job (the ROS closed loop) -> results/
#   bash contgrasp.sh test   # set up (idempotent), run ruff and mypy, then the whole test suite
#                            # (extra arguments go to pytest: bash contgrasp.sh test -k boundary)
#   bash contgrasp.sh setup  # only set up
#
# Set-up creates a virtual environment inside the checkout, installs the project with its
# dependencies (numpy, scipy, numba, matplotlib), the ROS layer with the pinned ros-jazzy-* wheels
# (extras ros, ros-wheels), the test extras and the benchmarks' reference simulator (pyelastica,
# extra "bench"), re-installs only when pyproject.toml changed, and warms numba's cache of the
# compiled kernels. Everything talks over loopback only.
#
# Python 3.11, 3.12 or 3.13: by default the first of python3.11, python3.12, python3.13, python3
# that runs, in .venv/; PYTHON=python3.12 bash contgrasp.sh test picks one (a command, a path, or a
# version pyenv has installed but not selected), in .venv-3.12/.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here"

supported() {  # the interpreter runs and is one of the supported versions
    "$1" -c 'import sys; sys.exit(not (3, 11) <= sys.version_info[:2] <= (3, 13))' 2>/dev/null
}

resolve_python() {  # a command or path that runs; pyenv's shims run only its selected versions
    local cand="$1" dir
    if supported "$cand"; then
        echo "$cand"
        return 0
    fi
    if [[ "$cand" =~ ^python(3\.[0-9]+)$ ]] && command -v pyenv >/dev/null 2>&1; then
        for dir in $(ls -d "$(pyenv root)/versions/${BASH_REMATCH[1]}".* 2>/dev/null | sort -rV); do
            if supported "$dir/bin/$cand"; then
                echo "$dir/bin/$cand"
                return 0
            fi
        done
    fi
    return 1
}

find_python() {
    local cand
    if [ -n "${PYTHON:-}" ]; then
        resolve_python "$PYTHON" && return 0
        echo "contgrasp.sh: PYTHON=$PYTHON is not a Python 3.11, 3.12 or 3.13 that runs here" >&2
        return 1
    fi
    for cand in python3.11 python3.12 python3.13 python3; do
        resolve_python "$cand" && return 0
    done
    echo "contgrasp.sh: Python 3.11, 3.12 or 3.13 is required (python3.11, python3.12, python3.13 or python3)" >&2
    return 1
}

if [ -n "${PYTHON:-}" ]; then
    base_python="$(find_python)"
    venv="$here/.venv-$("$base_python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
else
    venv="$here/.venv"
fi
py="$venv/bin/python"
stamp="$venv/.contgrasp-setup"

export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
user_ros_log_dir="${ROS_LOG_DIR:-}"
export ROS_LOG_DIR="${ROS_LOG_DIR:-$here/results/ros_log}"
export MPLBACKEND=Agg
# the ament index search path (what sourcing a ROS 2 setup script provides): this venv
export AMENT_PREFIX_PATH="$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"

setup() {
    if [ ! -x "$py" ]; then
        local base
        base="${base_python:-$(find_python)}"
        if ! "$base" -m venv "$venv" 2>/dev/null; then
            # Debian ships venv/ensurepip separately
            if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
                apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null
                rm -rf "$venv"
                "$base" -m venv "$venv"
            else
                echo "contgrasp.sh: '$base -m venv' failed; install python3-venv" >&2
                exit 1
            fi
        fi
    fi
    local want
    want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
    if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
        echo "== installing contgrasp and its dependencies into ${venv#"$here"/}"
        # (pip's own messages, the build backend's warnings among them, are kept in the venv's
        # pip-install.log and shown only when the install fails; pip writes the dependencies' byte
        # code, which Python does not where PYTHONDONTWRITEBYTECODE is set: without it every
        # process would compile numpy, scipy and rclpy again, ~1 CPU-s for each node started)
        local log="$venv/pip-install.log"
        if ! { "$py" -m pip install --quiet --upgrade pip &&
            "$py" -m pip install --quiet -e ".[ros,ros-wheels,test,msgs,bench]"; } >"$log" 2>&1; then
            cat "$log" >&2
            echo "contgrasp.sh: installing the project failed (log: $log)" >&2
            exit 1
        fi
        echo "$want" >"$stamp"
    fi
    # The interface package is compiled with the machine's cmake and C/C++ compilers.
    if ! command -v cmake >/dev/null 2>&1 || ! command -v g++ >/dev/null 2>&1; then
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
            apt-get update -qq && apt-get install -y -qq cmake g++ make >/dev/null
        else
            echo "contgrasp.sh: cmake and g++ are needed to build msgs_schema/; install them" >&2
            exit 1
        fi
    fi
    "$py" msgs_schema/build_into_venv.py
    "$py" -m contgrasp_ros.install_resources >/dev/null  # editable installs skip data files
    # the project's own byte code too (an editable install compiles none; only what changed)
    "$py" -m compileall -q -j 0 contgrasp_core contgrasp_ros tests >/dev/null
    # Compile the rod engine's numba kernels once (a tiny simulation; numba caches the machine code
    # in contgrasp_core/rod/__pycache__), so the first real run does not pay ~10-17 s of compilation;
    # when the cache is current this only loads it (under a second).
    "$py" -m contgrasp_core.warmup
    mkdir -p "$ROS_LOG_DIR"
}

run_main() {
    mkdir -p results
    echo "== closed-loop grasp through the ROS 2 graph (separate processes, lock-step sim time)"
    local bag
    bag="bags/run_$(date +%Y%m%d_%H%M%S)"
    "$venv/bin/contgrasp-launch" --bag "$bag" --plot results/closed_loop.png --summary-file results/closed_loop.json
    echo "== figure: results/closed_loop.png, summary: results/closed_loop.json, recording: $bag/"
    echo "== offline analysis of the recording (no ROS needed) -> results/closed_loop_analysis.json"
    "$venv/bin/contgrasp" bag info "$bag"
    "$venv/bin/contgrasp" analyze "$bag" --json --plot results/closed_loop_from_bag.png >results/closed_loop_analysis.json
    for obj in circle ellipse deformed; do
        echo "== contact kinematics around the $obj -> results/kinematics_$obj.png"
        "$venv/bin/contgrasp" kinematics --object "$obj" --plot "results/kinematics_$obj.png" >/dev/null
    done
    # what the run left behind, and how big (each run adds a recording of ~13 MB)
    echo "== written: $(du -sh results | cut -f1) in results/ (overwritten by the next run), $(du -sh "$bag" | cut -f1) in $bag/ (one per run: remove old ones with rm -r bags/run_*)"
    echo "== the recording as CSV files (~33 MB): $venv/bin/contgrasp analyze $bag --csv results/closed_loop_csv"
}

run_checks() {
    # Static checks first (a few seconds): any finding fails the test command. Configured in
    # pyproject.toml ([tool.ruff], [tool.mypy]); the versions are pinned in the test extra.
    echo "== ruff check ."
    # (explicit returns: errexit does not reach into a function called from an && list)
    "$py" -m ruff check . || return 1
    echo "== mypy (contgrasp_core, contgrasp_ros)"
    "$py" -m mypy || return 1
}

run_tests() {
    run_checks || return 1
    # the tests' ROS logs go to a temporary directory (tests/conftest.py), not results/, unless set
    [ -n "$user_ros_log_dir" ] || unset ROS_LOG_DIR
    # A distinct DDS domain per test run keeps concurrent runs apart (ROS tests pick their own too).
    export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( ($$ % 90) + 10 ))}"
    # Two worker processes (pytest-xdist; CONTGRASP_TEST_WORKERS=1 for one, 0 for none), each
    # test file on one worker so a file's shared fixtures (a colcon build, a wheel) are made once.
    local workers="${CONTGRASP_TEST_WORKERS:-2}"
    if [[ ! "$workers" =~ ^[0-9]+$ ]]; then
        echo "contgrasp.sh: CONTGRASP_TEST_WORKERS must be a whole number, got '$workers'" >&2
        return 2
    fi
    # (the files in the order tests/shard.py gives them: the heaviest first)
    "$py" -m pytest -n "$workers" --dist loadfile --no-loadscope-reorder "$@"
}

cmd="${1:-}"
[ $# -gt 0 ] && shift
case "$cmd" in
    setup) setup ;;
    run) setup && run_main ;;
    test) setup && run_tests "$@" ;;
    *)
        echo "usage: bash contgrasp.sh {run|test|setup} [pytest args]" >&2
        exit 2
        ;;
esac
