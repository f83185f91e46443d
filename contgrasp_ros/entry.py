"""The ROS layer's console scripts (``contgrasp-launch``, ``contgrasp-simulator``, ...).

Each imports its module only when run, so that where the layer's dependencies are missing (a
library-only install, README "Install") it prints one line naming what to install and exits
with code 2 instead of an import traceback; a Ctrl-C that comes before the command handles its
own (while it imports) ends it as that command's Ctrl-C does, without a traceback.
``python -m contgrasp_ros.entry EXECUTABLE ARGS...`` runs one of them by its name in
``lib/contgrasp_ros/`` (how ``contgrasp-launch`` starts its node processes).
"""

from __future__ import annotations

import importlib
import signal
import sys
from collections.abc import Callable
from types import ModuleType

from contgrasp_ros.layer import missing

__all__ = ["launcher", "rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality",
           "foxglove_bridge", "mcap_recorder", "container"]


def _import_deferring_sigint(module: str) -> ModuleType:
    """Import ``module`` with SIGINT held back until the import is done: an interrupt that lands
    inside a compiled extension's import (rclpy's, numba's) was seen ignored, fatal (exit -2) or
    a traceback; held back, it arrives after the import as an ordinary KeyboardInterrupt."""
    if not hasattr(signal, "pthread_sigmask"):  # (not on Windows)
        return importlib.import_module(module)
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return importlib.import_module(module)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _entry(module: str, interrupted: int = 0) -> Callable[[], int]:
    """The console script running ``module.main()``; ``interrupted`` is its exit code on a Ctrl-C
    that ``main`` does not handle itself (a node stops with 0, as on any Ctrl-C; the launcher 130)."""

    def main() -> int:
        name = sys.argv[0].rsplit("/", 1)[-1]
        try:
            code: int = _import_deferring_sigint(module).main()
        except ModuleNotFoundError as exc:  # at import, or a dependency the command imports later
            error = missing(exc)
            if error is None:
                raise
            print(f"{name}: error: {error}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:  # (before the command's own handler: a launcher stopping a starting node)
            if interrupted:
                print(f"{name}: interrupted", file=sys.stderr)
            return interrupted
        return code

    main.__doc__ = f"Run ``{module}.main()``."
    return main


launcher = _entry("contgrasp_ros.launcher.cli", interrupted=130)
rod_simulator = _entry("contgrasp_ros.nodes.rod_simulator")
boundary_sensor = _entry("contgrasp_ros.nodes.boundary_sensor")
grasp_controller = _entry("contgrasp_ros.nodes.grasp_controller")
grasp_quality = _entry("contgrasp_ros.nodes.grasp_quality")
foxglove_bridge = _entry("contgrasp_ros.nodes.foxglove_bridge")
mcap_recorder = _entry("contgrasp_ros.nodes.mcap_recorder")
container = _entry("contgrasp_ros.nodes.container")


if __name__ == "__main__":
    executable = sys.argv[1] if len(sys.argv) > 1 else ""
    if executable not in __all__ or executable == "launcher":
        print(f"usage: python -m contgrasp_ros.entry {{{','.join(n for n in __all__ if n != 'launcher')}}} [ARGS...]",
              file=sys.stderr)
        raise SystemExit(2)
    sys.argv = [executable, *sys.argv[2:]]
    raise SystemExit(globals()[executable]())
