"""What the command line prints is short and true: usage errors are one line with
one ``error:`` and a ``--help`` hint on every command; text summaries print scalars and short
values (arrays only with --json); quality-map's text shows the optimum; simulate warns about a
zero-order hold known to be unstable and offers the graph's first-order hold; bag info prints
QoS with rclpy's field names."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from contgrasp_core.cli import main

BIN = Path(sys.executable).parent
SAMPLE_BAG = Path(__file__).resolve().parents[1] / "bags" / "paper_grasp.mcap"
COMMANDS = [[], ["kinematics"], ["quality-map"], ["grasp"], ["figures"], ["simulate"], ["bag"], ["bag", "info"],
            ["bag", "recover"], ["replay"], ["analyze"]]
VALUED = {"kinematics": "--rho0", "quality-map": "--psi-steps", "grasp": "--nodes", "figures": "--out",
          "simulate": "--dt", "bag info": None, "bag recover": None, "replay": "--rate", "analyze": "--csv"}


def _usage_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    with pytest.raises(SystemExit) as info:
        main(argv)
    captured = capsys.readouterr()
    assert info.value.code == 2 and captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    return lines[0]


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "contgrasp")
def test_an_unknown_option_is_one_line_naming_it(capsys: pytest.CaptureFixture[str], command: list[str]) -> None:
    line = _usage_error(capsys, [*command, "--no-such-option"])
    prog = " ".join(["contgrasp", *command])
    assert line.startswith(f"{prog}: error: ") and line.endswith(f"(see '{prog} --help')"), line
    assert line.count("error:") == 1
    # named even where a required argument is missing too (argparse reports only that)
    assert "--no-such-option" in line


@pytest.mark.parametrize("command", [c for c in VALUED if VALUED[c]])
def test_a_missing_value_is_one_line(capsys: pytest.CaptureFixture[str], command: str) -> None:
    words = command.split()
    extra = ["x.mcap"] if command in ("replay", "analyze") else []
    line = _usage_error(capsys, [*words, *extra, str(VALUED[command])])
    prog = f"contgrasp {command}"
    assert line == f"{prog}: error: argument {VALUED[command]}: expected one argument  (see '{prog} --help')"


@pytest.mark.parametrize("argv", [["--no-such-option"], ["--duration"], ["--duration", "x"]])
def test_launcher_usage_errors_are_one_line(argv: list[str]) -> None:
    proc = subprocess.run([str(BIN / "contgrasp-launch"), *argv], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and proc.stdout == ""
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("contgrasp-launch: error: ") and line.endswith("(see 'contgrasp-launch --help')")
    assert line.count("error:") == 1


@pytest.mark.heavy
@pytest.mark.parametrize("argv", [["contgrasp", "bag", "info", str(SAMPLE_BAG)], ["contgrasp", "kinematics", "--json"]])
def test_a_reader_that_closed_stdout_gets_no_traceback(argv: list[str]) -> None:
    """``contgrasp bag info X | head -2``: the reader is gone before the output is; the command
    ends quietly with exit code 1 (Python's recipe for SIGPIPE), nothing on stderr."""
    read, write = os.pipe()
    os.close(read)
    try:
        proc = subprocess.run([str(BIN / argv[0]), *argv[1:]], stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert (proc.returncode, proc.stderr) == (1, "")


def _parsers(parser: argparse.ArgumentParser, name: str) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """``parser`` (named ``name``) and every subcommand's parser below it."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, p in action.choices.items():
                yield from _parsers(p, f"{name} {sub}")


def test_every_command_has_a_description_and_every_option_a_help() -> None:
    """What ``--help`` shows: what the command does, and what each option means."""
    from contgrasp_core.cli import build_parser
    from contgrasp_ros.launcher.cli import _parser

    commands = [*_parsers(build_parser(), "contgrasp"), *_parsers(_parser(), "contgrasp-launch")]
    assert {"contgrasp figures", "contgrasp replay", "contgrasp bag recover", "contgrasp quality-map"} <= {n for n, _ in commands}
    for name, parser in commands:
        assert parser.description, f"{name} --help has no description"
        for action in parser._actions:
            if not isinstance(action, argparse._SubParsersAction):
                assert action.help, f"{name} --help: {'/'.join(action.option_strings) or action.dest} has no help"


def test_quality_map_help_explains_the_grid_and_the_executor(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["quality-map", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--d-min D_MIN nearest base distance from the object, paper units (default 3)" in text
    assert "--d-max D_MAX farthest base distance" in text
    assert "--executor {serial,processes,dask} run the poses one after the other (serial), on a process pool" in text


def _text(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    assert main(argv) == 0
    return capsys.readouterr().out


def _assert_short(text: str) -> list[str]:
    lines = text.strip().splitlines()
    for line in lines:
        assert len(line) <= 200, line
        if not line.startswith("(in --json only: "):  # (that line names what is left out)
            assert line.count(",") <= 12, line  # no long list printed
    return lines


@pytest.mark.parametrize("solver", ["fast", "forward-backward"])
def test_grasp_text_prints_scalars_not_arrays(capsys: pytest.CaptureFixture[str], solver: str) -> None:
    code = main(["grasp", "--nodes", "80", "--solver", solver, "--max-iterations", "20"])
    assert code == (0 if solver == "fast" else 1)  # (20 sweep steps are no solution: printed, then exit 1)
    lines = _assert_short(capsys.readouterr().out)
    keys = {ln.split(":", 1)[0] for ln in lines}
    assert {"cost", "converged", "iterations", "constraints.min_rho", "message"} <= keys
    assert "rho" not in keys and "kappa" not in keys  # along the arm: --json only
    assert lines[-1].startswith("(in --json only: ") and "kappa" in lines[-1]
    if solver == "forward-backward":  # 20 costs: named, not printed
        assert "cost_history" in lines[-1]


def test_quality_map_text_shows_the_optimum(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    saved = tmp_path / "map"
    out = json.loads(_text(capsys, ["quality-map", "--psi-steps", "4", "--d-steps", "2", "--nodes", "50",
                                    "--executor", "serial", "--out", str(saved), "--json"]))
    text = _text(capsys, ["quality-map", "--load", str(saved)])
    lines = _assert_short(text)
    assert "dict of" not in text and "see --json)" not in text
    for metric in ("Q1", "Q2", "Q3"):
        opt = out["optimum"][metric]
        (line,) = [ln for ln in lines if ln.startswith(f"optimum {metric}: ")]
        assert f"{opt['value']:.6g}" in line and f"psi {opt['psi']:.4g} rad" in line and f"d {opt['d']:.4g}" in line
    best = [ln for ln in lines if ln.strip().startswith("best grid pose")]
    assert len(best) == 3 and all("Q1" in ln and "Q2" in ln and "Q3" in ln for ln in best)
    one = _text(capsys, ["quality-map", "--load", str(saved), "--metric", "Q2"])
    assert "optimum Q2: " in one and "optimum Q1" not in one


def test_quality_map_text_says_why_there_is_no_optimum(capsys: pytest.CaptureFixture[str]) -> None:
    """Not computed because of --no-optimise (also with --metric), or none because no pose is
    valid: the line names the one that holds."""
    from contgrasp_core.cli.quality import format_text

    argv = ["quality-map", "--psi-steps", "1", "--d-steps", "1", "--nodes", "40", "--executor", "serial", "--no-optimise"]
    for metric in ("all", "Q2"):
        lines = _text(capsys, [*argv, "--metric", metric]).splitlines()
        assert "optimum: not computed (--no-optimise)" in lines and not any("no valid pose" in ln for ln in lines)
    out = json.loads(_text(capsys, [*argv, "--json"]))
    assert "optimum: none (no valid pose)" in format_text({**out, "n_valid": 0}).splitlines()


# ---------------------------------------------------------------- simulate: holds

def test_zoh_warning_names_the_first_order_hold() -> None:
    from dataclasses import replace

    from contgrasp_core.cli.simulate import zoh_warning
    from contgrasp_core.scenario import PAPER

    rod = PAPER.rod
    warning = zoh_warning(rod, 0.002, "zero-order")
    assert warning is not None and "--hold first-order" in warning and "\n" not in warning
    assert zoh_warning(rod, 0.001, "zero-order") is not None  # measured unstable at 1 ms
    assert zoh_warning(rod, 0.0005, "zero-order") is None  # 0.5 ms agrees with the continuous loop
    assert zoh_warning(rod, 0.002, "first-order") is None
    assert zoh_warning(rod, None, "zero-order") is None  # continuous feedback
    assert zoh_warning(replace(rod, n_elements=400), 0.0005, "zero-order") is not None  # a finer tip is faster


def _simulate(argv: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(BIN / "contgrasp"), "simulate", *argv, "--json"], capture_output=True, text=True, timeout=300)


@pytest.mark.heavy
def test_simulate_warns_once_for_an_unstable_zoh_and_not_for_first_order() -> None:
    zoh = _simulate(["--control-period", "0.002", "--duration", "0.01"])
    assert zoh.returncode == 0, zoh.stderr
    (line,) = zoh.stderr.strip().splitlines()
    assert line.startswith("contgrasp simulate: warning: ") and "--hold first-order" in line
    assert json.loads(zoh.stdout)["control"] == "zoh 0.002 s"
    foh = _simulate(["--control-period", "0.002", "--duration", "0.01", "--hold", "first-order"])
    assert foh.returncode == 0 and foh.stderr == ""
    assert json.loads(foh.stdout)["control"] == "first-order hold 0.002 s"
    bad = _simulate(["--hold", "first-order"])
    assert bad.returncode == 2 and "--control-period" in bad.stderr


def test_first_order_hold_stays_calm_where_the_zoh_flutters() -> None:
    """The paper's arm at the graph's 2 ms: held to first order the swing-in is smooth; held
    constant the tip flutters (node speeds of ~1 m/s and 4x the penetration by 0.4 s)."""
    from dataclasses import replace

    from contgrasp_core.control import paper_gains
    from contgrasp_core.objects import ROD_SCALE, ObjectSpec
    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop
    from contgrasp_core.rod.session import record_sampled
    from contgrasp_core.scenario import PAPER

    obj = ObjectSpec.from_cli(None, None, ROD_SCALE)
    cfg = ClosedLoopConfig(duration=0.4, control_period=0.002, record_period=0.01)
    gains = paper_gains(PAPER.rod, obj.radius)
    foh = record_sampled(PAPER.with_object(obj, loop=replace(cfg, record_period=None)), cfg.record_period)
    zoh = run_closed_loop(RodSystem(PAPER.rod, Obstacle(obj.boundary())), gains, cfg)
    assert foh.t[-1] == pytest.approx(0.4) and zoh.t[-1] == pytest.approx(0.4)
    assert foh.max_speed[-1] < 0.2 < 0.5 < zoh.max_speed[-1]
    assert foh.penetration_ratio.max() < 0.5 * zoh.penetration_ratio.max()
    assert np.all(np.isfinite(foh.x))


# ---------------------------------------------------------------- bag info: QoS

def test_qos_text_uses_rclpy_field_names() -> None:
    from contgrasp_ros.cli import qos_text

    unknown = {"history": "unknown", "depth": 0, "reliability": "reliable", "durability": "volatile"}
    last = {"history": "keep_last", "depth": 10, "reliability": "best_effort", "durability": "transient_local"}
    assert qos_text([unknown]) == " | QoS (1 publisher): Reliability: reliable, History (Depth): unknown, Durability: volatile"
    assert "History (Depth): keep_last (10)" in qos_text([last])
    both = qos_text([unknown, unknown, last])
    assert both.startswith(" | QoS (3 publishers): 2 x Reliability: reliable") and "1 x Reliability: best_effort" in both
    assert qos_text([]) == "" and qos_text("") == ""


@pytest.mark.skipif(not SAMPLE_BAG.exists(), reason="the sample bag is not in this checkout")
def test_bag_info_prints_qos_readably(capsys: pytest.CaptureFixture[str]) -> None:
    text = _text(capsys, ["bag", "info", str(SAMPLE_BAG)])
    topics = [ln for ln in text.splitlines() if ln.strip().startswith("Topic: ")]
    assert topics and all("| QoS (" in ln and "Reliability: " in ln and "Durability: " in ln for ln in topics)
    assert "unknown 0" not in text
    assert "Durability: transient_local" in next(ln for ln in topics if "/contgrasp/object" in ln)


@pytest.mark.parametrize("hold", ["first-order", "zero-order"])
def test_max_penetration_is_over_every_control_step_recorded_or_not(hold: str) -> None:
    """One definition of ``max_penetration``: the largest rod-surface
    penetration over every control step, as the ROS simulator's session reports it, whatever the
    record period. Truth: the same run recorded at every step (record_period None)."""
    from dataclasses import replace

    from contgrasp_core.control import paper_gains
    from contgrasp_core.objects import ROD_SCALE, ObjectSpec
    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig, ClosedLoopResult, run_closed_loop
    from contgrasp_core.rod.session import record_sampled
    from contgrasp_core.scenario import PAPER

    obj = ObjectSpec.from_cli(None, None, ROD_SCALE)
    gains = paper_gains(PAPER.rod, obj.radius)
    config = ClosedLoopConfig(duration=0.6, control_period=0.002)

    def run(record_period: float | None) -> ClosedLoopResult:
        if hold == "first-order":
            return record_sampled(PAPER.with_object(obj, loop=config), record_period)
        return run_closed_loop(RodSystem(PAPER.rod, Obstacle(obj.boundary())), gains,
                               replace(config, record_period=record_period))

    every, sparse = (run(rp) for rp in (None, 0.01))
    assert len(every.t) > 4 * len(sparse.t)
    truth = float(every.penetration.max())
    assert truth > 0 and sparse.max_penetration == pytest.approx(truth, rel=1e-9)
    assert every.max_penetration == pytest.approx(truth, rel=1e-9)
    assert sparse.max_penetration_ratio == pytest.approx(float(every.penetration_ratio.max()), rel=1e-9)
    assert sparse.penetration.max() < truth  # the sampled series alone misses the peak
