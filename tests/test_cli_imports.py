"""``contgrasp --version``, ``--help`` and every subcommand's ``--help`` import neither scipy nor
matplotlib: a subcommand imports what it computes with only when it runs (docs/design.md,
section 8), so the command answers these at once."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

# One interpreter answers every case in turn: modules only accumulate, so the first case after
# which a heavy module is loaded is the one that loads it. After --version and --help, the cases
# are the parser's own subcommands (those of installed packages included, nested ones such as
# ``bag info`` too).
CHILD = """
import argparse, contextlib, io, json, sys
from contgrasp_core.cli import build_parser, main

HEAVY = ("scipy", "matplotlib")

def commands(parser, prefix=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*prefix, name)
                yield from commands(sub, (*prefix, name))

out = []

def run(argv):
    with contextlib.redirect_stdout(io.StringIO()) as text:
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    loaded = sorted({m.split(".")[0] for m in sys.modules} & set(HEAVY))
    out.append({"argv": argv, "code": code, "printed": bool(text.getvalue()), "heavy": loaded})

run(["--version"])
run(["--help"])
for command in commands(build_parser()):
    run([*command, "--help"])
print(json.dumps(out))
"""


def test_version_and_every_help_import_neither_scipy_nor_matplotlib() -> None:
    proc = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=120,
                          cwd=Path(__file__).resolve().parents[1], env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr[-3000:]
    cases = json.loads(proc.stdout.splitlines()[-1])
    names = {" ".join(c["argv"]) for c in cases}
    assert {"--version", "--help", "simulate --help", "grasp --help", "holding-study --help"} <= names
    assert all(c["code"] == 0 and c["printed"] for c in cases), [c for c in cases if c["code"] != 0 or not c["printed"]]
    heavy = [(" ".join(c["argv"]), c["heavy"]) for c in cases if c["heavy"]]
    assert heavy == [], f"first case that imports scipy or matplotlib: {heavy[0]}"
