"""The Fast DDS discovery profile of the launcher's graph: its node processes get it in their
environment, its own participant (the monitor) while it is created (:func:`discovery_profile_set`;
the launcher's environment is left as it was, so tests that run it in-process do not pass the
profile on to nodes they start by hand).

Participants started at the same moment - the launcher's node processes - often miss each
other's first discovery announcements on loopback and then meet only at the next periodic
announcement, 2-3 s later. ``config/fastdds_discovery.xml`` announces 30 times every 100 ms
instead of Fast DDS's 5 (the steady-state period is unchanged); rmw_fastrtps applies
``ROS_AUTOMATIC_DISCOVERY_RANGE`` on top of it.

Only the launcher's node processes get it. Nodes started by hand keep Fast DDS's defaults: with the profile,
a by-hand sensor started 3 s before a simulator whose first state fails (it exits 1 s later,
``tests/test_by_hand.py``) missed the simulator's failure status in 5 of 6 tries (0 of 5
without; the cause inside Fast DDS was not found).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, MutableMapping
from importlib import resources
from pathlib import Path

__all__ = ["discovery_profile", "use_discovery_profile", "discovery_profile_set"]

_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


def discovery_profile() -> Path:
    """The packaged profile, ``contgrasp_ros/config/fastdds_discovery.xml``."""
    return Path(str(resources.files("contgrasp_ros") / "config" / "fastdds_discovery.xml"))


def use_discovery_profile(environ: MutableMapping[str, str] = os.environ) -> None:
    """Point ``FASTRTPS_DEFAULT_PROFILES_FILE`` at :func:`discovery_profile` unless the
    environment already names a profile file (the user's own wins). Before ``rclpy.init``."""
    if not any(environ.get(name) for name in _VARIABLES):
        environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(discovery_profile())


@contextlib.contextmanager
def discovery_profile_set(environ: MutableMapping[str, str] = os.environ) -> Iterator[None]:
    """:func:`use_discovery_profile` for the duration of the block, then the variables as they
    were (Fast DDS reads the profile file when a process creates its first participant)."""
    saved = {name: environ.get(name) for name in _VARIABLES}
    use_discovery_profile(environ)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                environ.pop(name, None)
            else:
                environ[name] = value
