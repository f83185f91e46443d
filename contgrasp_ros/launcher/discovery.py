"""The Fast DDS discovery profile of the launcher's graph (``config/fastdds_discovery.xml``: more
discovery announcements at start, so processes started together meet at once).

The launcher's node processes get it in their environment and its own participant (the monitor)
while it is created (:func:`discovery_profile_set`; the launcher's environment is left as it
was). Nodes started by hand keep Fast DDS's defaults. Why, and what was measured: docs/design.md,
"Start-up".
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
