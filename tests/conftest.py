"""Test-wide settings: loopback-only DDS discovery and a distinct ROS domain per test."""

from __future__ import annotations

import itertools
import os
import random
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import settings
from shard import (  # noqa: F401 - CI shares the heavy tests out (shard.py)
    pytest_addoption,
    pytest_collection_modifyitems,
    pytest_runtest_logreport,
    shard_from_env,
    store_durations,
)

# CI (.ci/run sets HYPOTHESIS_PROFILE=ci) draws the same examples every run, so a submission's
# verdict does not depend on the draw; developers' runs keep exploring new random examples.
settings.register_profile("ci", derandomize=True, database=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_LOG_DIR", os.path.join(tempfile.gettempdir(), "contgrasp_ros_log"))
os.environ.setdefault("MPLBACKEND", "Agg")
# every process a test starts prints its Python stacks if it crashes (a node that segfaulted on
# shutdown once under load in CI, exit -11: the next time says where)
os.environ.setdefault("PYTHONFAULTHANDLER", "1")
# what sourcing a ROS 2 setup script provides: the ament index search path (this venv)
os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)

_domains = itertools.count()
DOMAIN_CLASS_VARIABLE = "CONTGRASP_TEST_DOMAIN_CLASS"
# a random starting point per test run: two concurrent runs on one machine (a developer's and
# a benchmark's, say) rarely share a domain, and graphs on different domains cannot cross-talk
_BASE = random.SystemRandom().randint(0, 100)
# pytest-xdist's workers (bash contgrasp.sh test runs two) each take the domains of their own
# residue class, and so do the shards CI runs at once (.ci/run): worker i of W in shard K of N
# uses only the domains congruent to (K - 1) W + i + 1 modulo N W, never another's
_SHARD, _SHARDS = shard_from_env() or (1, 1)
_WORKERS = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
_CLASSES = _SHARDS * _WORKERS
_CLASS = (_SHARD - 1) * _WORKERS + int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))
if os.environ.get(DOMAIN_CLASS_VARIABLE):  # (a pytest run a test started: its parent's class, never another's)
    _CLASS, _CLASSES = (int(v) for v in os.environ[DOMAIN_CLASS_VARIABLE].split("/"))


def domain_class() -> dict[str, str]:
    """What a pytest run started by a test (``colcon test`` of the workspace) needs in its
    environment to take its domains from this worker's class: with CI's two legs at once, a
    random domain of its own had met the other leg's simulator (a rod state from nowhere)."""
    return {DOMAIN_CLASS_VARIABLE: f"{_CLASS}/{_CLASSES}"}


def fresh_domain_id() -> int:
    """A ROS_DOMAIN_ID in 1..101 for one test: distinct within this run, across its workers and
    concurrent shards too."""
    return ((_BASE + next(_domains)) % (101 // _CLASSES)) * _CLASSES + _CLASS + 1


if _CLASSES > 1:
    # what a test inherits when it picks no domain (the launcher's default, `ros2` commands):
    # this worker's own, never another worker's
    os.environ["ROS_DOMAIN_ID"] = str(fresh_domain_id())


def spin_until(executor: Any, cond: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Spin ``executor`` (20 ms turns) until ``cond()`` holds; False after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)
        if cond():
            return True
    return False


@pytest.fixture
def ros_context():  # type: ignore[no-untyped-def]
    """An initialised rclpy context on a fresh domain; shut down after the test."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=fresh_domain_id())
    yield ctx
    if ctx.ok():
        rclpy.shutdown(context=ctx)


@pytest.fixture
def make(ros_context):  # type: ignore[no-untyped-def]
    """Build nodes on the test's context (``make(NodeClass, **parameters)``, wall time unless
    ``use_sim_time`` is given: no /clock here, the stamp rule runs against wall time);
    destroyed after the test."""
    from rclpy.parameter import Parameter

    nodes = []

    def build(cls, **params):  # type: ignore[no-untyped-def]
        params.setdefault("use_sim_time", False)
        node = cls(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        nodes.append(node)
        return node

    yield build
    for n in nodes:
        n.destroy_node()


class Sink:
    """Stands in for a node's publisher: keeps what would have been published (and has no
    subscribers). A serialized message (the loop's nodes publish bytes, contgrasp_ros.plumbing.cdr) is
    kept as rclpy's own deserializer reads it as ``msg_type``."""

    def __init__(self, msg_type: Any = None) -> None:
        self.msgs: list[Any] = []
        self.msg_type = msg_type

    def publish(self, msg: Any) -> None:
        if isinstance(msg, bytes):
            from rclpy.serialization import deserialize_message

            assert self.msg_type is not None, "a Sink for serialized messages needs their type"
            msg = deserialize_message(msg, self.msg_type)
        self.msgs.append(msg)

    def get_subscription_count(self) -> int:
        return 0


def pytest_sessionfinish(session, exitstatus):  # type: ignore[no-untyped-def]
    """Store the heavy tests' durations when asked (shard.py); leave no Fast DDS shared-memory
    files of killed test processes in /dev/shm."""
    store_durations(session)
    try:
        from contgrasp_ros.launcher.processes import clean_shared_memory
    except ImportError:  # (a core-only environment)
        return
    clean_shared_memory()


def _sigint_ignored() -> bool:
    """Whether SIGINT is ignored in this process at the OS level (what a subprocess inherits;
    C code can set it behind Python's back, so /proc, not :func:`signal.getsignal`)."""
    import signal

    try:
        with open("/proc/self/status") as fh:
            mask = next(int(line.split()[1], 16) for line in fh if line.startswith("SigIgn:"))
    except (OSError, StopIteration):
        return signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    return bool(mask & (1 << (signal.SIGINT - 1)))


@pytest.fixture(autouse=True)
def _sigint_handled(request: pytest.FixtureRequest) -> Any:
    """Every test starts with SIGINT handled, and one that leaves it ignored is named (a warning).
    An ignored SIGINT is inherited by every subprocess started afterwards, and the tests that
    Ctrl-C a command (the study, replay, idle nodes) then wait in vain. Two sources: whatever
    started the run (a non-interactive shell starts a background job, ``cmd &``, as a CI runner
    or nohup may start ``.ci/run``, with SIGINT ignored: what failed them in whole runs on
    2026-11-26), put back silently; and a test: those that run nodes in-process do so on purpose
    (a node's clean-up ignores SIGINT until its process exits:
    ``contgrasp_ros.plumbing.runtime._ignore_interrupts``), any other is a finding."""
    import signal
    import warnings

    if _sigint_ignored():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if _sigint_ignored():
        warnings.warn(f"{request.node.nodeid} left SIGINT ignored; restored", RuntimeWarning, stacklevel=1)
        signal.signal(signal.SIGINT, signal.default_int_handler)
