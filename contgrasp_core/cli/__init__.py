"""The ``contgrasp`` command.

Every computing subcommand accepts ``--json`` and then prints exactly one JSON object on
stdout (keys documented in docs/cli.md). Errors become one line on stderr,
``contgrasp COMMAND: error: MESSAGE``: exit code 2 for bad usage or input (argparse errors,
:class:`~contgrasp_core.errors.InputError`), 1 for a failed run
(:class:`~contgrasp_core.errors.RunFailure`, any other exception); ``--debug`` shows the
whole traceback instead, with the same exit code. Other packages add subcommands through the ``contgrasp.cli`` entry point
group (the ROS layer's recordings: ``bag``, ``replay``, ``analyze``); this package never imports
them by name. ``python -m contgrasp_core.cli`` is the same command.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from importlib.metadata import entry_points
from typing import Any, NoReturn

import numpy as np

from .. import __version__
from ..errors import ContgraspError, FailedResult, exit_code, interruption, one_line

__all__ = ["ArgumentParser", "build_parser", "main", "report", "summary_lines", "closed_stdout_safe"]


class ArgumentParser(argparse.ArgumentParser):
    """argparse with usage errors on one line, ``PROG: error: WHAT  (see 'PROG --help')``,
    exit code 2 (argparse prints the whole usage, 7-9 lines for these commands). Subcommand
    parsers inherit the class, so ``PROG`` names the subcommand (``contgrasp grasp``)."""

    _argv: list[str] = []

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self._argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def _unknown_options(self) -> list[str]:
        """Option-like words of this parser's arguments that it does not know (a typo, usually)."""
        out = []
        for word in self._argv:
            if word == "--":
                break
            if not word.startswith("-") or word == "-" or self._negative_number_matcher.match(word):
                continue
            name = word.split("=", 1)[0]
            known = name in self._option_string_actions or (
                self.allow_abbrev and name.startswith("--") and any(o.startswith(name) for o in self._option_string_actions))
            if not known:
                out.append(word)
        return out

    def error(self, message: str) -> NoReturn:
        message = " ".join(message.split())
        if message.startswith("the following arguments are required"):
            # argparse checks the required arguments first: a mistyped option would be reported
            # as a missing positional (``contgrasp --josn`` -> "required: COMMAND")
            unknown = self._unknown_options()
            if unknown:
                message = f"unrecognized arguments: {' '.join(unknown)}; {message}"
        self.exit(2, f"{self.prog}: error: {message}  (see '{self.prog} --help')\n")


def report(prog: str, exc: BaseException) -> int:
    """Print ``exc`` as the one line ``PROG: error: MESSAGE`` on stderr; return its exit code
    (2 for an :class:`~contgrasp_core.errors.InputError`, else 1). An exception that is no
    :class:`~contgrasp_core.errors.ContgraspError` is a bug: its type leads the message."""
    text = one_line(exc)
    if not isinstance(exc, ContgraspError):
        text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    print(f"{prog}: error: {text or type(exc).__name__}", file=sys.stderr)
    return exit_code(exc)


def closed_stdout_safe(run: Callable[[], int]) -> int:
    """``run()``, its output flushed; a reader that closed stdout early (``contgrasp ... | head``)
    ends it quietly with exit code 1, the recipe of Python's docs ("Note on SIGPIPE" in the
    :mod:`signal` module): stdout goes to ``os.devnull``, so that the interpreter's last flush
    does not fail again."""
    try:
        try:
            return run()
        finally:  # (also after --help's SystemExit)
            sys.stdout.flush()
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


Registrar = Callable[[Any, list[argparse.ArgumentParser]], None]


def registrars() -> list[Registrar]:
    """The subcommand registrars other installed packages offer in the ``contgrasp.cli`` entry
    point group (the ROS layer's recording commands), by entry point name."""
    return [ep.load() for ep in sorted(entry_points(group="contgrasp.cli"), key=lambda ep: ep.name)]


def build_parser(extra: Sequence[Registrar] | None = None) -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered: the core's and those of ``extra``
    registrars (default: :func:`registrars`, what installed packages add)."""
    # (not at import time, so that the launcher, which only needs this module's parser class,
    # starts its node processes sooner; the subcommands import scipy and matplotlib only when
    # they run, so that --version and --help answer at once)
    from . import grasp, hold, holding_study, kinematics, quality, simulate

    common = ArgumentParser(add_help=False)
    common.add_argument("--json", action="store_true", help="print one JSON object with the results on stdout")
    common.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    parser = ArgumentParser(
        prog="contgrasp",
        description="Kinematics of continuum planar grasping: kinematics, optimal grasps, quality, control.",
    )
    parser.add_argument("--version", action="version", version=f"contgrasp {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    kinematics.add_parser(sub, [common])
    quality.add_parser(sub, [common])
    grasp.add_parsers(sub, [common])
    simulate.add_parser(sub, [common])
    hold.add_parser(sub, [common])
    holding_study.add_parser(sub, [common])
    for register in registrars() if extra is None else extra:
        register(sub, [common])
    return parser


def _to_jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _to_jsonable(obj.item())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def _number(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float | np.floating):
        return f"{float(value):.6g}"
    return str(value)


def _is_scalar(value: Any) -> bool:
    return value is None or isinstance(value, bool | int | float | str | np.generic)


def _short(value: Any) -> str | None:
    """A short text for ``value``, or None for an array-like (those are in --json only)."""
    if _is_scalar(value):
        text = _number(value)
        return text if len(text) <= 200 else text[:200] + " ..."
    if isinstance(value, list | tuple) and len(value) <= 6 and all(_is_scalar(v) for v in value):
        return "[" + ", ".join(_number(v) for v in value) + "]" if value else "[]"
    return None


def summary_lines(result: dict[str, Any], prefix: str = "") -> tuple[list[str], list[str]]:
    """``key: value`` lines for the scalars and short values of ``result`` (nested dicts flattened
    to ``key.sub``, floats to 6 digits), and the names of what is left out (arrays along the arm,
    grids): those are in --json."""
    lines: list[str] = []
    left: list[str] = []
    for key, value in result.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            sub_lines, sub_left = summary_lines(value, f"{name}.")
            lines += sub_lines
            left += sub_left
            continue
        text = _short(value)
        if text is None:
            left.append(name)
        else:
            lines.append(f"{name}: {text}")
    return lines, left


def _summary(result: dict[str, Any]) -> str:
    """The text result (without --json): scalars and short values, one per line; arrays are
    named on a last line and only printed by --json."""
    lines, left = summary_lines(result)
    if left:
        lines.append(f"(in --json only: {', '.join(left)})")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None, extra: Sequence[Registrar] | None = None) -> int:
    """Entry point of the ``contgrasp`` command; returns the process exit code."""
    return closed_stdout_safe(lambda: _main(argv, extra))


def _main(argv: Sequence[str] | None, extra: Sequence[Registrar] | None) -> int:
    try:  # the subcommands' modules load here: a Ctrl-C meanwhile ends as one during a command does
        parser = build_parser(extra)
    except KeyboardInterrupt:
        print("contgrasp: interrupted", file=sys.stderr)
        return 130
    args, unknown = parser.parse_known_args(argv)
    command = " ".join(c for c in (args.command, getattr(args, "bag_command", None)) if c)
    if unknown:  # argparse would name the top-level parser; the subcommand's help is the one to read
        ArgumentParser(prog=f"contgrasp {command}").error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        result = args.func(args)
        if args.json:
            text = json.dumps(_to_jsonable(result), allow_nan=False)
        else:
            text = getattr(args, "format_text", _summary)(result)
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - the CLI turns every failure into one line
        if interruption(exc) is not None:  # Ctrl-C (also inside a compiled kernel): the shell's code for SIGINT
            print(f"contgrasp {command}: interrupted", file=sys.stderr)
            return 130
        if args.debug:  # the whole traceback, and the same exit code as without --debug
            traceback.print_exc()
            return exit_code(exc)
        if isinstance(exc, FailedResult):  # a failed check that has a result: print it too
            result = exc.result
            print(json.dumps(_to_jsonable(result), allow_nan=False) if args.json else getattr(args, "format_text", _summary)(result))
        return report(f"contgrasp {command}", exc)
    print(text)
    return 0

