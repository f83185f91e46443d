"""``contgrasp-launch``: run the closed-loop grasp graph (ROS 2 launch/launch_ros are not wheels).

Starts ``rod_simulator``, ``boundary_sensor``, ``grasp_controller`` and ``grasp_quality`` as
separate processes (``--compose`` hosts some of the last three in one process; with
``--in-process`` all run as nodes of one executor in this process) with
a YAML parameter file, the ``ROS_DOMAIN_ID`` of ``--domain-id``, else the environment's,
else a random one (printed first on stderr), and loopback-only discovery; waits until the
graph is connected, then resumes the (paused) simulator; runs until the simulator reports it
finished (settled or ``--duration`` reached) and stops everything (SIGINT, then SIGTERM, then
SIGKILL). The summary is built from what travelled over the topics. The run is recorded to MCAP
by the ``mcap_recorder`` node (``--bag``, default ``bags/run_<time>``; ``--no-record`` skips it),
its messages logged in simulated time (``--bag-log-time``); a recording lost mid-run fails the
run (exit 1) unless ``--allow-unrecorded``.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import sys
import tempfile
import traceback
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path

import numpy as np

from contgrasp_core.cli import ArgumentParser, closed_stdout_safe, report
from contgrasp_core.cli.common import add_object_arguments, object_from_args
from contgrasp_core.control.hold_law import LAWS
from contgrasp_core.errors import InvalidParameterError, exit_code, one_line, refuse_ignored
from contgrasp_core.objects import ROD_SCALE
from contgrasp_core.outputs import check_output
from contgrasp_core.rod.body import MODES
from contgrasp_core.scenario import Scenario
from contgrasp_ros.bag import BagError
from contgrasp_ros.bag.writer import MIN_BAG_SIZE, check_file_name, check_split
from contgrasp_ros.layer import guarded
from contgrasp_ros.launcher.events import EventWriter, open_events
from contgrasp_ros.launcher.graph import compose_groups, default_params_file, launch_overrides, load_params, parameter_file
from contgrasp_ros.plumbing import topics


__all__ = ["main", "default_params_file", "load_params"]

PACKAGED_PARAMS = "contgrasp_ros/config/default.yaml (packaged)"
"""How a recording names the packaged parameter file (its run_info ``params_file``)."""


def _domain_id(given: int | None) -> int:
    """The run's ROS_DOMAIN_ID: ``--domain-id``, else ``$ROS_DOMAIN_ID`` when set, else random in 1..101."""
    if given is not None:
        domain, what = given, "--domain-id"
    elif os.environ.get("ROS_DOMAIN_ID", "").strip():
        text, what = os.environ["ROS_DOMAIN_ID"].strip(), "ROS_DOMAIN_ID"
        try:
            domain = int(text)
        except ValueError:
            raise InvalidParameterError(f"ROS_DOMAIN_ID must be an integer in 0..232, got {text!r}") from None
    else:
        return random.randint(1, 101)
    if not 0 <= domain <= 232:
        raise InvalidParameterError(f"{what} must be in 0..232, got {domain}")
    return domain


def _port(text: str) -> int:
    """``--foxglove PORT``: a TCP port, 0 = any free one."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be in 0..65535 (0 = any free port), got {port}")
    return port


def _namespace(text: str) -> str:
    """``--namespace NAME``: a ROS namespace (``r1``, ``/lab/r1``; ``/``, the default, is the root), made absolute."""
    if not re.fullmatch(r"/?([A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*)?", text):
        raise argparse.ArgumentTypeError(f"not a ROS namespace: {text!r} (letters, digits and _, parts separated by /)")
    return "/" + text.lstrip("/")


def _compose_groups(values: list[str], in_process: bool) -> list[tuple[str, ...]]:
    """The ``--compose`` groups (:func:`contgrasp_ros.launcher.graph.compose_groups`), separate processes only."""
    if values and in_process:
        raise InvalidParameterError("--compose groups node processes: it does not apply with --in-process")
    try:
        return compose_groups(values)
    except InvalidParameterError as exc:
        raise InvalidParameterError(f"--compose: {exc}") from None


def _parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="contgrasp-launch", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", type=Path, default=None, help="ROS 2 YAML parameter file (default: the packaged paper scenario)")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID for the graph (default: $ROS_DOMAIN_ID when set, else a random id 1..101); "
                        "printed on stderr at start")
    p.add_argument("--namespace", type=_namespace, default="/", metavar="NAME",
                   help="run the graph under this ROS namespace (its topics /NAME/contgrasp/..., its clock /NAME/clock), "
                        "e.g. two arms in one domain (default: none)")
    add_object_arguments(p, ROD_SCALE)
    p.add_argument("--law", choices=LAWS, default=None,
                   help="the controller's law: paper (eq. (19)), hold (the planned hold) or reactive (docs/holding.md) (default: the parameter file's)")
    p.add_argument("--object-mode", choices=MODES, default=None,
                   help="how the object moves: fixed (the paper), spring or free (default: the parameter file's)")
    p.add_argument("--max-muscle-stress", type=float, default=None, metavar="PA",
                   help="the muscles' largest stress, Pa: bounds each section's couple (docs/rod.md); 0: unbounded "
                   "(default: the parameter file's)")
    p.add_argument("--friction", type=float, default=None, metavar="MU",
                   help="Coulomb friction coefficient of the contact, stick-slip when > 0 (as contgrasp simulate "
                   "--friction); 0: frictionless, the paper (default: the parameter file's)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds to run at most (overrides the parameter file)")
    p.add_argument("--in-process", action="store_true", help="run all nodes in this process on one executor")
    p.add_argument("--executor", choices=("lean", "single", "events"), default=None,
                   help="with --in-process: contgrasp's lean single-threaded executor (default), rclpy's "
                        "SingleThreadedExecutor or rclpy's experimental events executor "
                        "(separate node processes always use the lean executor, see docs/ros.md)")
    p.add_argument("--compose", action="append", default=[], metavar="NODE,NODE[,...]",
                   help="host these nodes in one process (`contgrasp_ros.nodes.container`; any two or more of "
                        "boundary_sensor, grasp_controller, grasp_quality; the simulator always runs alone; repeatable): "
                        "boundary_sensor,grasp_controller saves the lock-step loop a process hop per step")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    p.add_argument("--plot", type=Path, default=None, help="write a Fig. 4-style figure of the run from the received topics")
    p.add_argument("--summary-file", type=Path, default=None, help="also write the JSON summary to this file")
    p.add_argument("--timeout", type=float, default=1800.0, help="wall-clock limit in seconds (default 1800)")
    p.add_argument("--bag", type=Path, default=None,
                   help="record to this bag folder (or .mcap file with --bag-layout file); default bags/run_<time>")
    p.add_argument("--bag-layout", choices=("folder", "file"), default=None,
                   help="a rosbag2 bag folder with metadata.yaml (default) or one .mcap file (default when --bag ends in .mcap)")
    p.add_argument("--no-record", action="store_true", help="do not record the run")
    p.add_argument("--foxglove", type=_port, nargs="?", const=8765, default=None, metavar="PORT",
                   help="serve the run live over the Foxglove WebSocket protocol on 127.0.0.1:PORT (default 8765; "
                        "0 = any free port): open ws://127.0.0.1:PORT in the Foxglove app")
    p.add_argument("--allow-unrecorded", action="store_true",
                   help="a recording lost mid-run (the recorder died) does not fail the run (default: exit 1)")
    p.add_argument("--bag-log-time", choices=("sim", "receive"), default=None,
                   help="log time of the recorded messages: simulated time (header stamp, else /clock; like ros2 bag "
                        "record --use-sim-time; the default) or the wall-clock receive time (the default with --respawn: "
                        "a restarted simulator starts its time over)")
    p.add_argument("--respawn", type=int, nargs="?", const=3, default=0, metavar="N",
                   help="restart a node process that dies, up to N times per node (N = 3 if omitted); "
                        "a restarted simulator starts the run again from the initial state")
    p.add_argument("--bag-exclude", default="", metavar="REGEX", help="do not record topics matching this regular expression")
    p.add_argument("--bag-decimate", type=float, default=0.0, metavar="SECONDS",
                   help="record rod state, contact and couple only every SECONDS of simulated time (plus the last "
                        "message); for small sample recordings (default 0: every message)")
    p.add_argument("--max-bag-duration", type=float, default=0.0, metavar="SECONDS",
                   help="split the bag folder into files of at most SECONDS each, like ros2 bag record (default 0: "
                        "one file); bounds the recorder's memory in long runs")
    p.add_argument("--max-bag-size", type=int, default=0, metavar="BYTES",
                   help=f"split the bag folder into files of about BYTES each (default 0: one file; else >= {MIN_BAG_SIZE})")
    p.add_argument("--events", default=None, metavar="FILE|-|fd:N",
                   help="write the launcher's events (domain id, node processes started/restarted/exited, simulator "
                        "resumed, finished) as JSON lines to FILE, stdout (-) or an inherited file descriptor (fd:N)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``contgrasp-launch``; returns the exit code (a failing node's code propagates).

    An error of the launcher itself is one line on stderr, ``contgrasp-launch: error: ...``:
    exit code 2 for bad usage or input (argparse, :class:`~contgrasp_core.errors.InputError`),
    1 otherwise (:class:`~contgrasp_core.errors.RunFailure`, any other exception); ``--debug``
    shows the traceback, with the same code. A reader that closed stdout early ends it quietly
    (:func:`~contgrasp_core.cli.closed_stdout_safe`)."""
    return closed_stdout_safe(lambda: _main(argv))


RECORDING_OPTIONS = ("--bag", "--bag-layout", "--bag-exclude", "--bag-decimate", "--bag-log-time", "--max-bag-duration",
                     "--max-bag-size", "--allow-unrecorded")
"""The options that set how the run is recorded: with ``--no-record`` they would do nothing."""


@contextmanager
def stdout_reserved(reserve: bool = True) -> Iterator[None]:
    """While the graph runs, file descriptor 1 points at stderr: stdout carries the summary only.
    The DDS library of an in-process graph (and a node process's native code) writes its own
    errors to descriptor 1, which once broke ``--json`` (a Fast DDS shared-memory port error
    before the summary)."""
    if not reserve:
        yield
        return
    with suppress(OSError):  # (a closed stdout is the summary's business, after the run)
        sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        with suppress(OSError):
            sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _main(argv: Sequence[str] | None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    events: EventWriter | None = None
    try:
        if args.no_record:
            dests = {option: option[2:].replace("-", "_") for option in RECORDING_OPTIONS}
            refuse_ignored([o for o, d in dests.items() if getattr(args, d) != parser.get_default(d)], "with --no-record",
                           "a recorded run")
        if args.events is not None:
            if args.events == "-" and args.json:
                raise InvalidParameterError("--events - and --json both write to stdout: give --events a file")
            events = open_events(args.events)
        with tempfile.TemporaryDirectory(prefix="contgrasp_params_") as folder:  # (a changed scenario's file)
            return guarded(_launch)(args, argv, Path(folder), events)  # (ROS missing: the one line naming it)
    except BrokenPipeError:  # (stdout closed by its reader: not the launcher's error)
        raise
    except Exception as exc:  # noqa: BLE001 - one line instead of a traceback (--debug shows it)
        if events is not None:
            events("finished", exit_code=exit_code(exc), error=one_line(exc) or type(exc).__name__)
        if args.debug:  # the whole traceback, and the same exit code as without --debug
            traceback.print_exc()
            return exit_code(exc)
        return report("contgrasp-launch", exc)
    finally:
        if events is not None:
            events.close()


def _launch(args: argparse.Namespace, argv: Sequence[str] | None, folder: Path, events: EventWriter | None = None) -> int:
    if not (np.isfinite(args.timeout) and args.timeout > 0):
        raise InvalidParameterError(f"--timeout must be a finite number > 0 (wall-clock seconds), got {args.timeout}")
    params_file = args.params or default_params_file()
    params = load_params(params_file)
    if args.duration is not None:
        if not (np.isfinite(args.duration) and args.duration > 0):
            raise InvalidParameterError(f"--duration must be a finite number > 0 (simulated seconds), got {args.duration}")
        params["rod_simulator"]["duration"] = float(args.duration)
    obj = object_from_args(args, ROD_SCALE) if args.object is not None or args.outline is not None else None
    changes = launch_overrides(params, obj, args.law, args.object_mode, args.max_muscle_stress, args.friction)
    if changes:  # (the nodes read the changed scenario from a file of their own, removed at the end)
        for node, values in changes.items():
            params[node].update(values)
        params_file = parameter_file(folder / "params.yaml", params)
    # the scenario's checks before any node: an impossible start (check_start), a holding law whose cage cannot close
    scenario = Scenario.from_ros_parameters(params)
    if scenario.law != "paper":  # (the rod engine and scipy only then: the launcher starts light)
        from contgrasp_core.holding.measure import check_reach

        check_reach(scenario)
    domain = _domain_id(args.domain_id)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    if events is not None:
        events("domain_id", domain_id=domain, mode="in-process" if args.in_process else "processes")
    if args.executor:
        if not args.in_process:
            raise InvalidParameterError("--executor applies to --in-process runs only")
        os.environ["CONTGRASP_EXECUTOR"] = args.executor
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_LOG_DIR", os.path.join(tempfile.gettempdir(), "contgrasp_ros_log"))
    from contgrasp_ros.launcher.graph_run import run_graph
    from contgrasp_ros.nodes.mcap_recorder import default_output

    record = None
    if not args.no_record:
        out = args.bag if args.bag is not None else Path(default_output())
        layout = args.bag_layout or ("file" if out.suffix == ".mcap" else "folder")
        if out.exists():
            raise InvalidParameterError(f"--bag {out} already exists (give a new folder or .mcap file name)")
        try:
            check_file_name(layout, out)
            re.compile(args.bag_exclude)
        except BagError as exc:
            raise InvalidParameterError(f"--bag / --bag-layout: {exc}") from exc
        except re.error as exc:
            raise InvalidParameterError(f"--bag-exclude {args.bag_exclude!r}: invalid regular expression: {exc}") from exc
        check_output(out, "--bag", folder=layout == "folder")
        # the file as the user named it (or the packaged one by name), never a path of this machine:
        # the parameters themselves are in ``params``
        run_info = {"params": params, "params_file": str(args.params) if args.params else PACKAGED_PARAMS,
                    "argv": list(sys.argv[1:] if argv is None else argv)}
        if not (np.isfinite(args.bag_decimate) and args.bag_decimate >= 0):
            raise InvalidParameterError(f"--bag-decimate must be a finite number >= 0 (seconds), got {args.bag_decimate}")
        try:
            check_split(layout, args.max_bag_duration, args.max_bag_size)
        except BagError as exc:
            raise InvalidParameterError(f"--max-bag-duration / --max-bag-size: {exc}") from exc
        record = {"output": out, "layout": layout, "run_info": run_info, "exclude_regex": args.bag_exclude,
                  "log_time": args.bag_log_time or ("receive" if args.respawn else "sim"),
                  "decimate_period": args.bag_decimate, "max_bag_duration": args.max_bag_duration,
                  "max_bag_size": args.max_bag_size}
    compose = _compose_groups(args.compose, args.in_process)
    if args.plot is not None:
        from contgrasp_core.figures.draw import check_figure_path  # (matplotlib: only when drawing)

        check_figure_path(args.plot, "--plot")
    if args.summary_file is not None:
        check_output(args.summary_file, "--summary-file")
    if args.respawn < 0 or (args.respawn and args.in_process):
        raise InvalidParameterError(f"--respawn takes N >= 0 and applies to separate node processes only, got {args.respawn}"
                                    + (" with --in-process" if args.in_process else ""))
    # (after the checks of the command line: bad usage stays one line)
    # (ros2cli is part of a ROS 2 install, not of this venv: say so instead of assuming it)
    print(f"[launcher] ROS_DOMAIN_ID={domain} (another terminal joins the graph with ROS_DOMAIN_ID={domain} "
          "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; with a ROS 2 install: ros2 topic echo "
          f"{topics.resolve(topics.QUALITY, args.namespace)})",
          file=sys.stderr, flush=True)
    with stdout_reserved(args.events != "-"):
        summary, code = run_graph(params, in_process=args.in_process, params_file=params_file, timeout=args.timeout,
                                  record=record, respawn=args.respawn, keep_history=args.plot is not None, events=events,
                                  foxglove=args.foxglove, allow_unrecorded=args.allow_unrecorded, compose=compose,
                                  namespace=args.namespace)
    summary["object"] = scenario.object.text()  # (as every command names it: docs/cli.md, "Objects")
    summary["domain_id"] = domain
    summary["mode"] = "in-process" if args.in_process else "processes"
    if args.plot is not None and summary.get("history"):
        from contgrasp_core.figures.run import run_figure

        run_figure(summary, params, str(args.plot))
        summary["plot"] = str(args.plot)
    summary.pop("history", None)
    for broken in (summary.get("validity") or {}).get("broken", []):
        print(f"contgrasp-launch: warning: the run left the model's validity, so it is not settled: {broken}", file=sys.stderr)
    if args.summary_file is not None:  # (checked before the run)
        args.summary_file.parent.mkdir(parents=True, exist_ok=True)
        args.summary_file.write_text(json.dumps(summary, indent=1))
    if events is not None:
        events("finished", exit_code=code, error=summary.get("error"))
    if args.json:
        print(json.dumps(summary))
    else:  # as the ``contgrasp`` subcommands print theirs: ``key.sub: value``, floats to 6 digits
        from contgrasp_core.cli import summary_lines

        keys = ("mode", "settled", "settle_time_s", "sim_time_s", "steps", "wall_time_s", "loop_wall_time_s",
                "real_time_factor", "step_wall_ms", "missed_deadlines", "late_couples",
                "mean_abs_rho_ratio_minus_1_contact", "max_abs_rho_ratio_minus_1_contact",
                "mean_abs_alpha_minus_half_pi_contact", "max_abs_alpha_minus_half_pi_contact",
                "contact_nodes", "contact_length", "max_penetration",
                "final_quality", "bag", "restarts", "faults", "exit_codes", "error")
        lines, _ = summary_lines({key: summary[key] for key in keys if key in summary})
        print("\n".join(lines))
    if code != 0 and summary.get("error"):  # (a failed run says so in one line on stderr too, as every command does)
        print(f"contgrasp-launch: error: {summary['error']}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
