"""One object, one name.

Every command prints the object by :meth:`contgrasp_core.objects.ObjectSpec.text`
(``circle:4``, ``ellipse:8,4``, ``outline:FILE`` with the file name as given), and what it
prints is what ``--object`` takes back; ``contgrasp analyze`` names a recording's object the
same way. The help of every command matches docs/cli.md, and no error suggests an option the
command refuses.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from contgrasp_core.cli import main
from contgrasp_core.objects import FIG2_SCALE, ROD_SCALE, ObjectScale, ObjectSpec
from contgrasp_core.scenario import PAPER
from contgrasp_ros.launcher import cli as launcher_cli
from contgrasp_ros.recordings import cli_analyze
from contgrasp_ros.recordings.analysis import object_name
from contgrasp_ros.recordings.run_data import load_run

ROOT = Path(__file__).resolve().parents[1]
KIDNEY = ROOT / "tests" / "data" / "kidney_outline.csv"
BAG = ROOT / "bags" / "paper_grasp.mcap"
CLI_DOC = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")

# each command at its cheapest: the smallest grid / duration its options allow
COMMANDS: dict[str, tuple[ObjectScale, list[str]]] = {
    "kinematics": (FIG2_SCALE, ["--nodes", "21"]),
    "grasp": (FIG2_SCALE, ["--nodes", "50"]),
    "quality-map": (FIG2_SCALE, ["--psi-steps", "1", "--d-steps", "1", "--d-max", "3", "--nodes", "20",
                                 "--executor", "serial", "--no-optimise"]),
    "simulate": (ROD_SCALE, ["--duration", "0.01", "--nodes", "11"]),
    "hold": (ROD_SCALE, ["--nodes", "11"]),  # the measurement itself is stubbed (test below)
    "holding-study": (FIG2_SCALE, ["--psi-steps", "1", "--d-steps", "1", "--d-max", "3", "--nodes", "11",
                                   "--duration", "0.01", "--directions", "1", "--executor", "serial"]),
}
OBJECTS = ("circle", "ellipse", "outline")


def object_arguments(kind: str, scale: ObjectScale, tmp_path: Path) -> list[str]:
    """``--object`` / ``--outline`` for ``kind`` in the scale's units (a built-in shape with
    parameters that differ from the scale's defaults; the test outline, in metres at rod scale)."""
    if kind == "circle":
        return ["--object", "circle:4" if scale is FIG2_SCALE else "circle:0.02"]
    if kind == "ellipse":
        return ["--object", "ellipse:8,4" if scale is FIG2_SCALE else "ellipse:0.03,0.015"]
    if scale is FIG2_SCALE:
        return ["--outline", str(KIDNEY)]
    path = tmp_path / "kidney_m.csv"  # 5 mm per paper unit, centred at the rod scenario's (8, 8) cm
    np.savetxt(path, np.loadtxt(KIDNEY, delimiter=",", skiprows=2) * 0.005 + 0.08, delimiter=",", header="x, y", comments="")
    return ["--outline", str(path)]


def expected_name(args: list[str]) -> str:
    """The canonical name of what ``args`` give: the shape text as written, ``outline:FILE``."""
    option, value = args
    return value if option == "--object" else f"outline:{value}"


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``contgrasp ARGV``: exit code (argparse's usage errors included), stdout, stderr."""
    try:
        code = main(argv, extra=[cli_analyze.add_parser])
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture
def stub_holding(monkeypatch: pytest.MonkeyPatch) -> None:
    """``contgrasp hold`` without its minute of physics: the name is made before the measurement."""
    monkeypatch.setattr("contgrasp_core.cli.hold.measure_holding", lambda *_: SimpleNamespace(to_dict=dict))


@pytest.mark.heavy
@pytest.mark.parametrize("kind", OBJECTS)
@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_prints_the_object_by_its_one_name(command: str, kind: str, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str], stub_holding: None) -> None:
    scale, options = COMMANDS[command]
    given = object_arguments(kind, scale, tmp_path)
    extra = ["--out", str(tmp_path / "study.jsonl")] if command == "holding-study" else []
    code, out, err = run([command, *given, *options, *extra, "--json"], capsys)
    assert code == 0, err
    name = json.loads(out)["object"]
    assert name == expected_name(given)
    # the name round-trips: --object takes it back as the same object
    assert ObjectSpec.parse(name, scale) == ObjectSpec.from_cli(*(
        (given[1], None) if given[0] == "--object" else (None, given[1])), scale)


@pytest.mark.parametrize("kind", OBJECTS)
@pytest.mark.parametrize("command", ["kinematics", "grasp", "quality-map"])
def test_the_text_output_names_the_object_the_same_way(command: str, kind: str, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    scale, options = COMMANDS[command]
    given = object_arguments(kind, scale, tmp_path)
    code, out, err = run([command, *given, *options], capsys)
    assert code == 0, err
    assert f"object: {expected_name(given)}\n" in out


def test_an_outline_named_as_printed_is_taken_back(capsys: pytest.CaptureFixture[str]) -> None:
    """``--object outline:FILE`` (the printed name) is the same object as ``--outline FILE``."""
    code, out, err = run(["kinematics", "--object", f"outline:{KIDNEY}", "--nodes", "21", "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["object"] == f"outline:{KIDNEY}"
    assert ObjectSpec.parse(f"outline:{KIDNEY}") == ObjectSpec.from_outline(KIDNEY)


def test_names_are_exact_numbers() -> None:
    for text in ("circle:0.1234567891", "ellipse:8,4", "deformed:5,0.15,3,0.3"):
        assert ObjectSpec.parse(text).text() == text
    assert ObjectSpec.parse("circle").text() == "circle:5"  # every parameter, the defaults too


def test_figures_names_its_objects(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["figures", "--nodes", "50", "--no-maps", "--out", str(tmp_path), "--json"], capsys)
    assert code == 0, err
    objects = json.loads(out)["objects"]
    assert {k: v["object"] for k, v in objects.items()} == {k: ObjectSpec.parse(k).text() for k in objects}


# ------------------------------------------------------------------ analyze
@pytest.mark.skipif(not BAG.is_file(), reason="bags/paper_grasp.mcap is not present")
def test_analyze_names_a_fixed_object(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["analyze", str(BAG), "--json"], capsys)
    assert code == 0, err
    result = json.loads(out)
    assert result["object"] == PAPER.object.text() == "circle:0.025"
    assert result["object_motion"] is None  # fixed: no motion
    code, out, err = run(["analyze", str(BAG)], capsys)
    assert code == 0 and "object: circle:0.025\n" in out, err


@pytest.mark.skipif(not BAG.is_file(), reason="bags/paper_grasp.mcap is not present")
def test_analyze_names_the_object_from_its_boundary_without_parameters() -> None:
    """A recording without the run's parameters: the name comes from the boundary message."""
    run_data = load_run(BAG)
    assert object_name(replace(run_data, params=None)) == object_name(run_data) == "circle:0.025"


def test_analyze_names_an_outline_by_its_file_without_reading_it() -> None:
    params: dict[str, dict[str, Any]] = {"rod_simulator": {"object": "outline", "object_outline": "gone/mine.csv"}}
    run_data = SimpleNamespace(params=params, boundary=None)
    assert object_name(run_data) == "outline:gone/mine.csv"  # type: ignore[arg-type]


# ------------------------------------------------------------------ help, errors and docs/cli.md
def test_holding_study_errors_suggest_only_what_it_takes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_file = str(tmp_path / "s.jsonl")
    code, _, err = run(["holding-study", "--object", "banana", "--out", out_file], capsys)
    assert code == 2 and "banana" in err and "circle[:R]" in err and "outline:FILE.csv" in err
    code, _, err = run(["holding-study", "--object", "circle", "--outline", str(KIDNEY), "--out", out_file], capsys)
    assert code == 2 and "not allowed with argument --object" in err
    # d_max too far for a small circle: the message names what to change, an option the command has
    code, _, err = run(["holding-study", "--object", "circle:3", "--out", out_file], capsys)
    assert code == 2 and "d_max = 13" in err and "--d-max" in err
    assert "--d-max" in _options(_help(["holding-study", "--help"], capsys))


def _help(argv: list[str], capsys: pytest.CaptureFixture[str], entry: Any = None) -> str:
    with pytest.raises(SystemExit) as exc:
        (entry or (lambda a: main(a, extra=[])))(argv)
    assert exc.value.code == 0
    return capsys.readouterr().out


def _options(help_text: str) -> list[str]:
    """The long options of an argparse help text (its option lines, not the descriptions)."""
    names: list[str] = []
    for line in help_text.splitlines():
        if re.match(r"^  -", line):
            names += re.findall(r"--[\w-]+", re.split(r"\s{2,}", line.strip())[0])
    return [n for n in names if n != "--help"]


def _doc_section(title: str) -> str:
    """The docs/cli.md section whose heading starts with ``title``."""
    sections = {part.split("\n", 1)[0]: part for part in re.split(r"^## ", CLI_DOC, flags=re.M)[1:]}
    found = [text for head, text in sections.items() if head.startswith(title)]
    assert len(found) == 1, f"docs/cli.md has no single section {title!r}"
    return found[0]


def _undocumented(options: list[str], section: str) -> list[str]:
    return [o for o in options if not re.search(re.escape(o) + r"(?![\w-])", section)]


CORE_COMMANDS = ["kinematics", "grasp", "figures", "quality-map", "simulate", "hold", "holding-study"]


@pytest.mark.parametrize("command", CORE_COMMANDS)
def test_every_option_of_a_command_is_in_docs_cli_md(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    options = [o for o in _options(_help([command, "--help"], capsys)) if o not in ("--json", "--debug")]
    assert options
    assert _undocumented(options, _doc_section(f"`contgrasp {command}`")) == []
    assert _undocumented(["--json", "--debug"], CLI_DOC.split("\n## ", 1)[0]) == []  # the common ones, up top


def test_every_launcher_option_is_in_docs_cli_md(capsys: pytest.CaptureFixture[str]) -> None:
    options = _options(_help(["--help"], capsys, launcher_cli.main))
    assert "--object" in options and "--outline" in options
    assert _undocumented(options, _doc_section("`contgrasp-launch`")) == []
