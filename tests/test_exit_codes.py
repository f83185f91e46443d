"""Errors mean what the README says: two families, two exit codes.

* every error class is in exactly one family: :class:`InputError` (a ``ValueError``) or
  :class:`RunFailure` (a ``RuntimeError``);
* every entry point - ``contgrasp`` (each subcommand), ``contgrasp-launch`` and the node mains
  (:func:`contgrasp_ros.plumbing.runtime.run_node`) - exits 2 with one line ``PROG: error: ...`` on bad
  input or bad usage, and 1 with one such line when a run on valid input fails.

The run failures are real where the system offers one: a Newton failure (``simulate --dt 5``),
an I/O error (``bag info /proc/self/mem`` reads EIO), a write beyond the file-size limit
(RLIMIT_FSIZE in a child process: EFBIG instead of a full disk), a message package that is not
installed (``replay``). Only the launcher's and run_node's start-up failures are injected.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from contgrasp_core.errors import (
    ContactValidityError,
    ContgraspError,
    DegenerateBoundaryError,
    InputError,
    IntegrationError,
    InvalidBoundaryError,
    InvalidParameterError,
    NotClosedError,
    RunFailure,
    SelfIntersectionError,
    WriteError,
    exit_code,
    output_error,
)
from contgrasp_core.optimal.discrete import ForwardSolveError, SingularSystemError
from contgrasp_core.rod.integrator import StepFailedError
from contgrasp_core.rod.session import SimulationDivergedError
from contgrasp_ros.bag import BagError, BagInputError, BagIOError

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "bags" / "paper_grasp.mcap"

INPUT_ERRORS = [InvalidParameterError, InvalidBoundaryError, NotClosedError, SelfIntersectionError, DegenerateBoundaryError,
                ContactValidityError, BagInputError]
RUN_FAILURES = [StepFailedError, SimulationDivergedError, SingularSystemError, ForwardSolveError, IntegrationError, WriteError,
                BagIOError]


def _ros_classes() -> tuple[list[type], list[type]]:
    from contgrasp_ros.plumbing.convert import MessageError
    from contgrasp_ros.plumbing.faults import FatalNodeError

    return [MessageError], [FatalNodeError]


# ----------------------------------------------------------------------------- the families
@pytest.mark.parametrize("cls", INPUT_ERRORS)
def test_input_errors_are_value_errors(cls: type) -> None:
    assert issubclass(cls, InputError) and issubclass(cls, ValueError) and issubclass(cls, ContgraspError)
    assert not issubclass(cls, RuntimeError) and not issubclass(cls, RunFailure)


@pytest.mark.parametrize("cls", RUN_FAILURES)
def test_run_failures_are_runtime_errors(cls: type) -> None:
    assert issubclass(cls, RunFailure) and issubclass(cls, RuntimeError) and issubclass(cls, ContgraspError)
    assert not issubclass(cls, ValueError) and not issubclass(cls, InputError)


def test_ros_error_classes_are_in_their_family() -> None:
    inputs, failures = _ros_classes()
    assert all(issubclass(c, InputError) and not issubclass(c, RuntimeError) for c in inputs)
    assert all(issubclass(c, RunFailure) and not issubclass(c, ValueError) for c in failures)


def test_every_error_class_is_in_exactly_one_family() -> None:
    """No class below the root is in neither family (it would exit 1 unexplained) or both;
    the only exception is BagError, the catch-all of the two bag classes (never raised)."""
    _ros_classes()  # import every module that defines an error class
    import contgrasp_ros.recordings.analysis  # noqa: F401
    import contgrasp_ros.recordings.replay  # noqa: F401

    seen, todo = [], [ContgraspError]
    while todo:
        cls = todo.pop()
        for sub in cls.__subclasses__():
            if sub not in seen:
                seen.append(sub)
                todo.append(sub)
    concrete = [c for c in seen if c not in (InputError, RunFailure, BagError)]
    assert len(concrete) >= len(INPUT_ERRORS) + len(RUN_FAILURES) + 2
    for cls in concrete:
        assert issubclass(cls, InputError) != issubclass(cls, RunFailure), cls
    assert issubclass(BagInputError, BagError) and issubclass(BagIOError, BagError)
    assert ContgraspError.__mro__[1] is Exception


def test_exit_code_and_output_error() -> None:
    assert exit_code(InvalidParameterError("x")) == 2 and exit_code(StepFailedError("x")) == 1
    assert exit_code(ZeroDivisionError()) == 1
    full = output_error("the figure a.png", OSError(28, "No space left on device"))
    assert isinstance(full, WriteError) and str(full) == "cannot write the figure a.png: No space left on device"
    assert isinstance(output_error("the figure a.png", ValueError("Format 'xyz' is not supported")), InvalidParameterError)


def test_library_raises_run_failures_and_input_errors_for_real() -> None:
    """The classes are what the library really raises: a Newton failure is a RuntimeError,
    a bad parameter of the same call a ValueError."""
    from contgrasp_ros.bag.reader import open_recording

    with pytest.raises(RuntimeError, match="Input/output error"):
        open_recording("/proc/self/mem")
    with pytest.raises(ValueError, match="no recording"):
        open_recording(ROOT / "no such bag")


# ----------------------------------------------------------------------------- contgrasp
def run_cli(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str]:
    """``contgrasp ARGV`` in-process: (exit code, the one stderr line)."""
    from contgrasp_core.cli import main

    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1, (argv, err)
    assert "Traceback" not in err and out == "", (argv, out)
    return code, lines[0]


BAD_INPUT = [
    (["kinematics", "--rho0", "-1"], "contgrasp kinematics: error: "),
    (["grasp", "--chi", "0", "--nodes", "40"], "contgrasp grasp: error: "),
    (["quality-map", "--nodes", "1", "--executor", "serial"], "contgrasp quality-map: error: "),
    (["figures", "--nodes", "2", "--no-maps"], "contgrasp figures: error: "),
    (["simulate", "--duration", "-1"], "contgrasp simulate: error: "),
    (["bag", "info", "/no/such/bag"], "contgrasp bag info: error: no recording at /no/such/bag"),
    (["bag", "recover", "/no/such/bag", "/tmp/never.mcap"], "contgrasp bag recover: error: no recording at /no/such/bag"),
    (["analyze", "/no/such/bag"], "contgrasp analyze: error: no recording at /no/such/bag"),
    (["replay", str(BAG), "--rate", "-1"], "contgrasp replay: error: "),
]


@pytest.mark.parametrize(("argv", "start"), BAD_INPUT, ids=[" ".join(a[:2]) for a, _ in BAD_INPUT])
def test_bad_input_exits_2_with_one_line(capsys: pytest.CaptureFixture[str], argv: list[str], start: str) -> None:
    code, line = run_cli(capsys, argv)
    assert code == 2 and line.startswith(start), line


@pytest.mark.parametrize("argv", [["grasp", "--rho0", "x"], ["kinematics", "--no-such-option"], ["bag", "info"], [],
                                  ["quality-map", "--metric", "Q4"]])
def test_usage_errors_are_one_line_with_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    code, line = run_cli(capsys, argv)
    prog = " ".join(["contgrasp", *[a for a in argv[:2] if not a.startswith("-")]])
    assert code == 2 and line.startswith(f"{prog}: error: ") and line.endswith(f"(see '{prog} --help')"), line
    assert "usage:" not in line


def test_help_still_works(capsys: pytest.CaptureFixture[str]) -> None:
    from contgrasp_core.cli import main

    with pytest.raises(SystemExit) as info:
        main(["grasp", "--help"])
    assert info.value.code == 0 and capsys.readouterr().out.startswith("usage: contgrasp grasp")


def test_newton_failure_in_simulate_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    """A step the integrator cannot take even after its halvings: a failed run, not bad input."""
    code, line = run_cli(capsys, ["simulate", "--dt", "5", "--duration", "2", "--nodes", "21"])
    assert code == 1 and line.startswith("contgrasp simulate: error: Newton failed to converge"), line


def test_io_error_reading_a_recording_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    code, line = run_cli(capsys, ["bag", "info", "/proc/self/mem"])
    assert code == 1 and line == "contgrasp bag info: error: cannot read /proc/self/mem: Input/output error", line


def _limited(size: int) -> Callable[[], None]:
    def limit() -> None:  # Python ignores SIGXFSZ: a write beyond the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))

    return limit


def _child(argv: list[str], *, fsize: int | None = None, module: str = "contgrasp_core.cli",
           timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-m", module, *argv], capture_output=True, text=True, timeout=timeout, env=env,
                          preexec_fn=None if fsize is None else _limited(fsize), cwd=ROOT)

NOWHERE = "/proc/contgrasp-none"
"""A folder no one can create, root included (``/proc`` takes no new files)."""

UNWRITABLE_OUTPUTS = [
    ["quality-map", "--psi-steps", "4", "--d-steps", "2", "--nodes", "40", "--no-optimise", "--executor", "serial",
     "--out", f"{NOWHERE}/map"],
    ["simulate", "--duration", "0.01", "--nodes", "11", "--plot", f"{NOWHERE}/fig.png"],
    ["simulate", "--duration", "0.01", "--nodes", "11", "--animate", f"{NOWHERE}/run.gif"],
    ["analyze", str(BAG), "--csv", f"{NOWHERE}/csv"],
    ["analyze", str(BAG), "--plot", f"{NOWHERE}/fig.png"],
    ["figures", "--nodes", "40", "--no-maps", "--out", f"{NOWHERE}/figures"],
    ["holding-study", "--psi-steps", "1", "--d-steps", "1", "--out", f"{NOWHERE}/study.jsonl"],
]


@pytest.mark.parametrize("argv", UNWRITABLE_OUTPUTS, ids=[" ".join(a[:1] + a[-2:-1]) for a in UNWRITABLE_OUTPUTS])
def test_an_output_that_cannot_be_written_is_refused_before_the_work(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    """(Were the work done first, the write would fail after it: exit 1.)"""
    code, line = run_cli(capsys, argv)
    command = " ".join(a for a in argv[:2] if not a.startswith("-") and "/" not in a)
    assert code == 2 and line.startswith(f"contgrasp {command}: error: {argv[-2]} {argv[-1]}"), line
    assert line.endswith(": cannot create a file in /proc (No such file or directory)"), line


def test_the_output_check_leaves_nothing_behind(tmp_path: Path) -> None:
    from contgrasp_core.outputs import check_output

    (tmp_path / "kept.json").write_text("as it was")
    assert check_output(tmp_path / "kept.json", "--out") == tmp_path / "kept.json"
    assert check_output(tmp_path / "new" / "deeper" / "s.json", "--out") == tmp_path / "new" / "deeper" / "s.json"
    assert check_output(tmp_path / "dir", "--csv", folder=True) == tmp_path / "dir"
    assert [p.name for p in tmp_path.iterdir()] == ["kept.json"] and (tmp_path / "kept.json").read_text() == "as it was"
    for path, folder, message in ((tmp_path / "kept.json" / "s.json", False, "kept.json is not a directory"),
                                  (tmp_path / "kept.json", True, "exists and is not a directory"),
                                  (tmp_path, False, "is a directory")):
        with pytest.raises(InvalidParameterError, match=message):
            check_output(path, "--out", folder=folder)


WRITE_FAILURES = [
    (["kinematics", "--plot", "{tmp}/k.png"], "cannot write the figure"),
    (["grasp", "--nodes", "40", "--max-iterations", "3", "--plot", "{tmp}/g.png"], "cannot write the figure"),
    (["quality-map", "--psi-steps", "1", "--d-steps", "1", "--nodes", "40", "--executor", "serial", "--out", "{tmp}/m"],
     "cannot save the quality map"),
    (["figures", "--nodes", "40", "--no-maps", "--out", "{tmp}/figs"], "cannot write the figure"),
    (["analyze", str(BAG), "--csv", "{tmp}/csv"], "cannot write CSV files"),
    (["bag", "recover", str(BAG), "{tmp}/rec.mcap"], "failed: File too large"),
]


@pytest.mark.parametrize(("argv", "needle"), WRITE_FAILURES, ids=[" ".join(a[:2]) for a, _ in WRITE_FAILURES])
def test_a_failing_write_exits_1(tmp_path: Path, argv: list[str], needle: str) -> None:
    """Valid arguments, but the output cannot be written (the file-size limit stands in for a
    full disk): exit 1 and one error line naming the file and the reason."""
    proc = _child([a.format(tmp=tmp_path) for a in argv], fsize=2048)
    errors = [line for line in proc.stderr.splitlines() if ": error: " in line]
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert len(errors) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    command = " ".join(a for a in argv[:2] if not a.startswith("-") and "/" not in a)
    assert proc.stderr.strip().splitlines()[-1] == errors[0]  # (a progress bar may precede it)
    assert errors[0].startswith(f"contgrasp {command}: error: ") and needle in errors[0] and "File too large" in errors[0]


@pytest.mark.heavy
def test_the_same_commands_succeed_without_the_limit(tmp_path: Path) -> None:
    """Control for the test above: the limit, not the arguments, made them fail."""
    proc = _child(["bag", "recover", str(BAG), str(tmp_path / "rec.mcap"), "--json"])
    assert proc.returncode == 0, proc.stderr[-2000:]
    proc = _child(["kinematics", "--plot", str(tmp_path / "k.png"), "--json"])
    assert proc.returncode == 0 and (tmp_path / "k.png").stat().st_size > 2048, proc.stderr[-2000:]


def test_replay_of_a_type_that_is_not_installed_exits_1(tmp_path: Path) -> None:
    """A valid recording whose message package this installation lacks: the run fails (1)."""
    from contgrasp_ros.bag.writer import BagWriter

    w = BagWriter(tmp_path / "alien.mcap", layout="file")
    w.add_topic("/alien", "alien_msgs/msg/Probe", definition="int32 x\n")
    w.write("/alien", b"\x00\x01\x00\x00\x07\x00\x00\x00", 1_000)
    w.close()
    proc = _child(["replay", str(tmp_path / "alien.mcap"), "--delay", "0"], timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr[-2000:]
    assert lines[0].startswith("contgrasp replay: error: cannot replay alien_msgs/msg/Probe"), lines


@pytest.mark.parametrize(("exc", "code"), [(StepFailedError("Newton failed"), 1), (WriteError("disk full"), 1),
                                           (ZeroDivisionError("a bug"), 1), (InvalidParameterError("rho0 must be > 0"), 2),
                                           (ContactValidityError("rho > 0 violated", s=0.1, condition="rho > 0"), 2)])
def test_core_main_maps_the_family_to_the_exit_code(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                                    exc: Exception, code: int) -> None:
    """contgrasp_core.cli.main: a RunFailure (or any other exception) raised inside a
    subcommand exits 1, an InputError 2; one line; --debug prints the traceback, same code."""
    from contgrasp_core import cli
    from contgrasp_core.cli import kinematics as cli_kinematics

    def broken(_args: object) -> None:
        raise exc

    monkeypatch.setattr(cli_kinematics, "run", broken)
    capsys.readouterr()
    assert cli.main(["kinematics"]) == code
    err = capsys.readouterr().err
    prefix = "" if isinstance(exc, ContgraspError) else f"{type(exc).__name__}: "
    assert err == f"contgrasp kinematics: error: {prefix}{exc}\n"
    assert cli.main(["kinematics", "--debug"]) == code  # (an input error once exited 1 with --debug)
    err = capsys.readouterr().err
    assert err.startswith("Traceback (most recent call last):") and f"{type(exc).__name__}: {exc}" in err


# ----------------------------------------------------------------------------- contgrasp-launch
def test_launcher_bad_input_and_usage_exit_2(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    from contgrasp_ros.launcher import cli as launcher

    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR"):  # the launcher sets them
        monkeypatch.setenv(var, os.environ.get(var, "0"))

    for argv, start in ((["--duration", "-1", "--no-record"], "contgrasp-launch: error: --duration must be"),
                        (["--no-record", "--respawn", "-2"], "contgrasp-launch: error: --respawn takes N >= 0"),
                        (["--no-record", "--friction", "-0.5"], "contgrasp-launch: error: friction must be a finite number >= 0"),
                        (["--no-record", "--friction", "nan"], "contgrasp-launch: error: friction must be a finite number >= 0"),
                        (["--bag", str(tmp_path), "--domain-id", "5"], f"contgrasp-launch: error: --bag {tmp_path} already exists"),
                        (["--params", str(tmp_path / "none.yaml")], "contgrasp-launch: error: cannot read parameter file"),
                        # (recording options the recorder would refuse: before, the graph started and the run failed)
                        (["--bag", str(tmp_path / "x.txt"), "--bag-layout", "file"],
                         f"contgrasp-launch: error: --bag / --bag-layout: a single-file recording must end in .mcap, got {tmp_path / 'x.txt'}"),
                        (["--no-record", "--events", "/proc/ev"], "contgrasp-launch: error: --events /proc/ev: "),
                        (["--bag", str(tmp_path / "b"), "--bag-exclude", "("],
                         "contgrasp-launch: error: --bag-exclude '(': invalid regular expression: missing ), unterminated subpattern")):
        capsys.readouterr()
        assert launcher.main(argv) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and err[0].startswith(start), err
    with pytest.raises(SystemExit) as info:
        launcher.main(["--duration", "soon"])
    err = capsys.readouterr().err.splitlines()
    assert info.value.code == 2 and len(err) == 1
    assert err[0] == ("contgrasp-launch: error: argument --duration: invalid float value: 'soon'  "
                      "(see 'contgrasp-launch --help')")


@pytest.fixture
def launched(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """The parameters each ``contgrasp-launch`` run hands to the graph (the run itself left out)."""
    import contgrasp_ros.launcher.graph_run

    runs: list[dict[str, Any]] = []

    def record(params: dict[str, Any], **_k: object) -> tuple[dict[str, Any], int]:
        runs.append(params)
        return {}, 0

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", record)
    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR"):  # the launcher sets them
        monkeypatch.setenv(var, os.environ.get(var, "0"))
    return runs


@pytest.mark.parametrize("text", ["", "{}\n", "grasp_controller:\n  ros__parameters:\n    law: reactive\n",
                                  "/rod_simulator:\n  ros__parameters: {}\n"])
def test_launcher_merges_a_partial_parameter_file_over_the_defaults(text: str, tmp_path: Path, launched: list[dict[str, Any]],
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from contgrasp_ros.launcher import cli as launcher
    from contgrasp_ros.launcher.graph import default_params_file, load_params

    params = tmp_path / "partial.yaml"
    params.write_text(text)
    assert launcher.main(["--params", str(params), "--no-record", "--json"]) == 0, capsys.readouterr().err
    want = load_params(default_params_file())
    if "law" in text:
        want["grasp_controller"]["law"] = "reactive"
    assert launched == [want]


@pytest.mark.parametrize(("text", "message"), [
    ("rod_simulatr:\n  ros__parameters:\n    duration: 1.0\n", "unknown node 'rod_simulatr'"),
    ("rod_simulator:\n  ros__parameters:\n    durtion: 1.0\n",
     "unknown parameter 'durtion' of rod_simulator (did you mean 'duration'?)"),
    ("/**:\n  ros__parameters:\n    lenght: 0.2\n", "unknown parameter 'lenght' of /**"),
    ("boundary_sensor:\n  ros__parameters:\n    law: hold\n", "unknown parameter 'law' of boundary_sensor"),
])
def test_launcher_refuses_an_unknown_node_or_parameter(text: str, message: str, tmp_path: Path, launched: list[dict[str, Any]],
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    from contgrasp_ros.launcher import cli as launcher

    params = tmp_path / "typo.yaml"
    params.write_text(text)
    capsys.readouterr()
    assert launcher.main(["--params", str(params), "--no-record"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"contgrasp-launch: error: {params}: {message}"), err
    assert launched == []


@pytest.mark.parametrize("option", [["--summary-file", "{tmp}/afile/s.json", "--no-record"],
                                    ["--plot", "{tmp}/afile/run.png", "--no-record"],
                                    ["--bag", f"{NOWHERE}/run"], ["--bag", f"{NOWHERE}/run.mcap"]])
def test_launcher_refuses_an_output_it_cannot_write_before_the_run(option: list[str], tmp_path: Path, launched: list[dict[str, Any]],
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from contgrasp_ros.launcher import cli as launcher

    (tmp_path / "afile").write_text("a file, not a folder")
    argv = [a.format(tmp=tmp_path) for a in option]
    capsys.readouterr()
    assert launcher.main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"contgrasp-launch: error: {argv[0]} {argv[1]}: "), err
    assert launched == []


def test_launcher_summary_to_a_closed_stdout_ends_quietly(tmp_path: Path, launched: list[dict[str, Any]],
                                                          monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The summary's reader (``contgrasp-launch --json | head -c 1``) is gone: exit 1, no error line."""
    from contgrasp_ros.launcher import cli as launcher

    class Closed:
        def __init__(self) -> None:
            self.fd = os.open(tmp_path / "fd", os.O_WRONLY | os.O_CREAT)

        def write(self, _text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self) -> None:
            raise BrokenPipeError(32, "Broken pipe")

        def fileno(self) -> int:
            return self.fd

    monkeypatch.setattr(sys, "stdout", Closed())
    capsys.readouterr()
    assert launcher.main(["--no-record", "--json"]) == 1
    assert [line for line in capsys.readouterr().err.splitlines() if not line.startswith("[launcher] ")] == []
    assert len(launched) == 1


@pytest.mark.parametrize(("options", "names"), [(["--bag", "DIR"], "--bag does"),
                                                (["--bag-decimate", "0.1", "--allow-unrecorded"],
                                                 "--bag-decimate, --allow-unrecorded do")])
def test_launcher_refuses_recording_options_with_no_record(options: list[str], names: str, launched: list[dict[str, Any]],
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    from contgrasp_ros.launcher import cli as launcher

    capsys.readouterr()
    assert launcher.main(["--no-record", *options]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"contgrasp-launch: error: {names} nothing with --no-record: {'it needs' if ',' not in names else 'they need'} a recorded run"]
    assert launched == []


def test_launcher_run_failure_exits_1(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A RunFailure out of the graph run (injected: a real one needs a whole graph) exits 1."""
    import contgrasp_ros.launcher.graph_run
    from contgrasp_ros.launcher import cli as launcher

    def diverged(*_a: object, **_k: object) -> None:
        raise SimulationDivergedError("simulation diverged: NaN/Inf in the rod state")

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", diverged)
    monkeypatch.setenv("ROS_DOMAIN_ID", os.environ.get("ROS_DOMAIN_ID", "0"))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    capsys.readouterr()
    assert launcher.main(["--no-record", "--domain-id", "7"]) == 1
    err = capsys.readouterr().err.splitlines()  # the launcher's log first (the domain), then one error line
    assert [line for line in err if not line.startswith("[launcher] ")] == ["contgrasp-launch: error: simulation diverged: NaN/Inf in the rod state"]
    assert err[0].startswith("[launcher] ROS_DOMAIN_ID=7 ")


# ----------------------------------------------------------------------------- node mains
@pytest.mark.parametrize(("exc", "code", "line"), [
    (InvalidParameterError("rate_hz must be > 0, got -5"), 2, "broken_node: error: invalid parameter: rate_hz must be > 0, got -5"),
    (StepFailedError("Newton failed"), 1, "broken_node: error: Newton failed"),
])
def test_run_node_start_up_errors(capsys: pytest.CaptureFixture[str], exc: Exception, code: int, line: str) -> None:
    from contgrasp_ros.plumbing.runtime import run_node

    def broken_node() -> None:
        raise exc

    capsys.readouterr()
    assert run_node(broken_node, args=[]) == code  # type: ignore[arg-type]
    assert capsys.readouterr().err.splitlines() == [line]


def test_run_node_stopped_while_the_node_is_built_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    """SIGINT/SIGTERM during the node's construction (the launcher stopping its graph because
    another node failed to start) shuts rclpy's context down, and the constructor's next rcl call
    fails ('publisher's context is invalid'): a stop, exit 0, not a failure with a traceback."""
    import rclpy

    from contgrasp_ros.plumbing.runtime import run_node

    def interrupted_node() -> None:
        node = rclpy.create_node("interrupted_node")
        rclpy.shutdown()  # (what rclpy's signal handler does)
        node.declare_parameter("p", 1.0)  # publishes a parameter event on the dead context

    capsys.readouterr()
    assert run_node(interrupted_node, args=[]) == 0  # type: ignore[arg-type]
    assert capsys.readouterr().err == ""


def test_node_processes_use_the_lean_executor_whatever_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/ros.md: node processes always use the lean single-threaded executor (an EventsExecutor
    in a node process hung the graph after resuming and ignored SIGINT/SIGTERM); CONTGRASP_EXECUTOR
    is the launcher's choice only, so not even a bad value reaches a node."""
    import rclpy

    from contgrasp_ros.plumbing.runtime import make_executor, run_node

    monkeypatch.setenv("CONTGRASP_EXECUTOR", "bogus")
    with pytest.raises(ValueError, match="CONTGRASP_EXECUTOR must be"):
        make_executor()

    def stopping_node() -> Any:
        node: Any = rclpy.create_node("stopping_node")
        node.stop_requested = True  # (FinishPolicy's flag: the node asks to stop at once)
        return node

    assert run_node(stopping_node, args=[]) == 0


def test_a_ctrl_c_inside_a_compiled_kernel_is_an_interruption(monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """contgrasp's commands end a Ctrl-C with one line and the shell's code 130, also when it
    lands inside a compiled kernel and comes out as the SystemError it causes; an error with no
    interrupt in its chain is none."""
    from contgrasp_core.cli import main, simulate
    from contgrasp_core.errors import interruption
    from test_node_faults import kernel_interrupted

    err = kernel_interrupted()
    assert isinstance(interruption(err), KeyboardInterrupt) and interruption(KeyboardInterrupt()) is not None
    cycle = RuntimeError("a")
    cycle.__context__ = ValueError("b")
    cycle.__context__.__context__ = cycle
    assert interruption(cycle) is None and interruption(SystemError("x")) is None

    def interrupted(*args: Any, **kwargs: Any) -> None:
        raise kernel_interrupted()

    monkeypatch.setattr(simulate, "run_scenario", interrupted)  # (where the stepping happens)
    capsys.readouterr()
    assert main(["simulate", "--duration", "0.01"]) == 130
    assert capsys.readouterr().err.splitlines() == ["contgrasp simulate: interrupted"]


def test_run_node_joins_rclpy_signal_thread_before_destroying_anything(monkeypatch: pytest.MonkeyPatch) -> None:
    """An interrupted node process: rclpy's signal thread triggers guard conditions and shuts the
    context down while the main thread cleans up, so the clean-up first joins that thread
    (uninstalling rclpy's handlers) and only then destroys the node and shuts rclpy down (a
    node once crashed on shutdown under load, exit -11)."""
    import rclpy

    from contgrasp_ros.plumbing import runtime

    order: list[str] = []
    monkeypatch.setattr(runtime, "uninstall_signal_handlers",
                        lambda: (order.append("joined"), rclpy.signals.uninstall_signal_handlers()))

    def interrupted_node() -> Any:
        node: Any = rclpy.create_node("interrupted_node")
        destroy = node.destroy_node
        node.destroy_node = lambda: (order.append("destroyed"), destroy())

        def interrupt() -> None:
            raise KeyboardInterrupt  # (what the first SIGINT raises in the spinning main thread)

        node.create_timer(0.001, interrupt)
        return node

    assert runtime.run_node(interrupted_node, args=[]) == 0
    assert order[:2] == ["joined", "destroyed"] and not rclpy.ok()

@pytest.mark.heavy
def test_node_with_bad_parameter_exits_2_and_recorder_with_failing_disk_exits_1(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Real node processes: a bad start-up parameter exits 2; a recorder whose writes fail
    (file-size limit) stops with exit 1 and one error line - the FatalNodeError must not be
    swallowed by the executor's guard against rclpy's own RuntimeErrors."""
    from conftest import fresh_domain_id

    monkeypatch.setenv("ROS_DOMAIN_ID", str(fresh_domain_id()))
    bad = _child(["--ros-args", "-p", "layout:=tape", "-p", f"output:={tmp_path / 'a'}"],
                 module="contgrasp_ros.nodes.mcap_recorder", timeout=60)
    assert bad.returncode == 2 and "McapRecorder: error: invalid parameter: layout must be one of" in bad.stderr, bad.stderr[-2000:]
    stray = _child(["--bogus", "--ros-args", "-p", f"output:={tmp_path / 'c'}"], module="contgrasp_ros.nodes.mcap_recorder",
                   timeout=60)
    assert stray.returncode == 2 and "McapRecorder: error: unrecognized arguments: --bogus" in stray.stderr, stray.stderr[-2000:]
    assert not (tmp_path / "c").exists()  # (it did not record)
    full = _child(["--ros-args", "-p", f"output:={tmp_path / 'b'}", "-p", "flush_period:=0.1"],
                  module="contgrasp_ros.nodes.mcap_recorder", fsize=100, timeout=60)
    assert full.returncode == 1, full.stderr[-2000:]
    errors = [line for line in full.stderr.splitlines() if line.startswith("McapRecorder: error: ")]
    assert len(errors) == 1 and "File too large" in errors[0], full.stderr[-2000:]



def test_launcher_without_ros_names_what_to_install(capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """In an install with the recording stack but no ROS 2 (``pip install 'contgrasp[ros]'``), a
    run needs rclpy: one line naming what to install, exit 2, not ``ModuleNotFoundError``."""
    from contgrasp_ros.launcher import cli as launcher

    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR"):  # the launcher sets them
        monkeypatch.setenv(var, os.environ.get(var, "0"))
    monkeypatch.setitem(sys.modules, "rclpy", None)  # (import rclpy: ModuleNotFoundError, name 'rclpy')
    for module in [m for m in sys.modules if m.startswith("contgrasp_ros.launcher.graph_run")]:
        monkeypatch.delitem(sys.modules, module)
    assert launcher.main(["--no-record"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("contgrasp-launch: error: needs ROS 2 Jazzy (module 'rclpy' is missing)"), err


@pytest.mark.parametrize(("script", "code", "line"), [("rod_simulator", 0, None),
                                                       ("launcher", 130, "contgrasp-launch: interrupted")])
def test_a_ctrl_c_while_a_command_imports_ends_it_as_its_own_ctrl_c(script: str, code: int, line: str | None,
                                                                   monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """A SIGINT before the command's own handler is installed (a launcher stopping a node that
    is still importing numba and rclpy) stops it as a Ctrl-C of the running command does: a node
    with 0, the launcher with 130 and one line, neither with a KeyboardInterrupt traceback."""
    import importlib

    from contgrasp_ros import entry

    def interrupted_import(name: str) -> Any:
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib, "import_module", interrupted_import)
    monkeypatch.setattr(sys, "argv", ["/venv/bin/" + ("contgrasp-launch" if script == "launcher" else "contgrasp-simulator")])
    assert getattr(entry, script)() == code
    err = capsys.readouterr().err
    assert err.splitlines() == ([] if line is None else [line]), err


def test_a_node_process_stopped_while_it_imports_exits_0_without_a_traceback() -> None:
    """The launcher's node command (``python -m contgrasp_ros.entry NODE``) SIGINTed 0.1 s after
    its start, while it still imports its modules (about 0.25 s here; the module run directly,
    ``python -m contgrasp_ros.nodes.rod_simulator``, exited -2 with a traceback there): exit 0,
    nothing on stderr. Truth: the stop a launcher makes of a graph whose nodes are starting."""
    from conftest import fresh_domain_id

    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(fresh_domain_id()))
    proc = subprocess.Popen([sys.executable, "-m", "contgrasp_ros.entry", "rod_simulator"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "Traceback" not in err, err[-2000:]
    unknown = subprocess.run([sys.executable, "-m", "contgrasp_ros.entry", "launcher"], capture_output=True, text=True, timeout=60)
    assert unknown.returncode == 2 and unknown.stderr.startswith("usage: python -m contgrasp_ros.entry {rod_simulator,"), unknown.stderr


def test_launcher_json_stays_clean_when_native_code_writes_to_stdout(monkeypatch: pytest.MonkeyPatch,
                                                                     capfd: pytest.CaptureFixture[str]) -> None:
    """``--json``: stdout carries the summary only. While the graph runs, what native code writes
    to file descriptor 1 (Fast DDS printed a shared-memory port error there, in-process, and the
    summary no longer parsed) goes to stderr."""
    import contgrasp_ros.launcher.graph_run
    from contgrasp_ros.launcher import cli as launcher

    def noisy(params: dict[str, Any], **_k: object) -> tuple[dict[str, Any], int]:
        os.write(1, b"[RTPS_TRANSPORT_SHM Error] Failed init_port\\n")
        return {"settled": True}, 0

    monkeypatch.setattr(contgrasp_ros.launcher.graph_run, "run_graph", noisy)
    for var in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR"):  # the launcher sets them
        monkeypatch.setenv(var, os.environ.get(var, "0"))
    assert launcher.main(["--no-record", "--in-process", "--json"]) == 0
    out, err = capfd.readouterr()
    assert json.loads(out)["settled"] is True and "Failed init_port" in err


@pytest.mark.heavy
def test_a_holding_law_that_cannot_close_is_refused_before_simulating(launched: list[dict[str, Any]],
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A 35 mm circle from the paper's base: the holding law's cage wraps 2.8 rad of it at rest
    and the close starts at pi, so the law would hover for the whole run (``contgrasp hold`` once
    ended, exit 1, with "no node touched the object"). ``hold`` and the launcher refuse it before
    any simulation, one line, exit 2; the paper's law on the same object runs."""
    from contgrasp_ros.launcher import cli as launcher

    proc = subprocess.run([sys.executable, "-m", "contgrasp_core.cli", "hold", "--law", "reactive", "--object", "circle:0.035"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("contgrasp hold: error: the holding law cannot close on circle:0.035 from this base")
    assert launcher.main(["--no-record", "--law", "reactive", "--object", "circle:0.035"]) == 2 and launched == []
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("contgrasp-launch: error: the holding law cannot close on circle:0.035"), err
    assert launcher.main(["--no-record", "--object", "circle:0.035"]) == 0 and len(launched) == 1
