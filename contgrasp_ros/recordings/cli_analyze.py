"""``contgrasp analyze BAG``: offline analysis of a recorded graph run, without ROS.

Registered by :func:`contgrasp_ros.cli.register`; the parsed namespace has
``func=cli_analyze.run``, which returns the JSON-able result
(:func:`contgrasp_ros.recordings.analysis.analyze`; keys in docs/analysis.md). Imports no ROS package, and
the recording stack (mcap) only when it runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from contgrasp_core.outputs import check_output
from contgrasp_ros.layer import guarded

__all__ = ["add_parser", "run"]


def add_parser(sub: Any, parents: list[argparse.ArgumentParser] | None = None) -> None:
    """Register the ``analyze`` subcommand (``parents``: the CLI's common ``--json/--debug`` parser)."""
    p = sub.add_parser(
        "analyze",
        help="analyse a recorded run offline: summary, recomputed contact/quality, CSV, plots",
        description=(
            "Rebuild the launcher's summary of a recorded run (bag folder or .mcap) and recompute the "
            "contact state and grasp quality from the recorded rod states with the nodes' own functions; "
            "max_recompute_error is the largest difference from the recorded topics. No ROS needed."
        ),
        parents=parents or [],
    )
    p.add_argument("bag", type=Path, metavar="BAG", help="recording: a rosbag2 bag folder (metadata.yaml + .mcap) or one .mcap file")
    if not parents:
        p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", type=Path, metavar="FILE",
                   help="write the Fig. 4-style figure to FILE and Q1..Q3 over time (recorded vs recomputed) to FILE_quality.SUFFIX")
    p.add_argument("--csv", type=Path, metavar="DIR", help="write rod_state.csv, contact.csv (long format) and quality.csv to DIR")
    p.set_defaults(func=run)


@guarded
def run(args: argparse.Namespace) -> dict[str, Any]:
    """Analyse ``args.bag``; the result dict (see :func:`contgrasp_ros.recordings.analysis.summarize`), or
    :class:`~contgrasp_ros.recordings.analysis.RecomputeMismatchError` (exit 1, the result printed first)
    when the recording does not recompute (:func:`contgrasp_ros.recordings.analysis.check`).
    The output paths are checked first, so a typo does not cost an analysis."""
    if args.plot is not None:
        from contgrasp_core.figures.draw import check_figure_path

        check_figure_path(args.plot)
    if args.csv is not None:
        check_output(args.csv, "--csv", folder=True)
    from contgrasp_ros.recordings.analysis import analyze, check

    out = analyze(args.bag, csv_dir=args.csv, plot=args.plot)
    check(out)  # exit 1 (after printing the result) when the recording does not recompute
    return out
