"""Benchmark: the paper's closed-loop grasp with and without the ROS 2 middleware.

The paper scenario (N = 100, 2 ms control period, until settled) run in one process six ways:
(a) core only (``run_sampled``); (b) the graph in one process, lock-step; (c) separate processes,
lock-step (the main job); (d) separate processes, wall-clock mode; (e), (f) as (c), (d) with the
sensor, controller and quality node composed into one process. Per way: milliseconds per step,
real-time factor, ratio to (a), missed deadlines, late couples, start-up time; (b), (c) and (e)
must end in (a)'s final state bit for bit. Medians of ``--repeat`` runs; results:
benchmarks/RESULTS.md.

Usage: AMENT_PREFIX_PATH=.venv .venv/bin/python benchmarks/ros_loop.py [--repeat 3] [--only a,c]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from contgrasp_core.rod.session import run_sampled
from contgrasp_core.scenario import PAPER
from contgrasp_ros.launcher.events import read_events
from contgrasp_ros.launcher.cli import default_params_file


COMPOSE = ("--compose", "boundary_sensor,grasp_controller,grasp_quality")


def core_only() -> dict[str, Any]:
    t0 = time.perf_counter()
    session = run_sampled(PAPER)
    wall = time.perf_counter() - t0
    obs = session.observe()
    return {"wall": wall, "steps": session.k, "sim": float(obs.t), "missed": 0, "late": 0, "startup": None, "x": obs.x}


def graph(params_file: Path, *extra: str) -> dict[str, Any]:
    exe = Path(sys.executable).parent / "contgrasp-launch"
    events = Path(tempfile.mkdtemp()) / "events.jsonl"
    t0 = time.time()
    out = subprocess.run([str(exe), "--json", "--no-record", "--params", str(params_file), "--events", str(events), *extra],
                         capture_output=True, text=True, timeout=3600)
    s = json.loads(out.stdout) if out.stdout.strip() else {}
    if out.returncode != 0:
        cause = s.get("error") or out.stderr.strip().splitlines()[-1:]
        return {"error": f"exit {out.returncode}: {cause}"}
    resumed = [e["time"] for e in read_events(events.read_text().splitlines()) if e["event"] == "resumed"]
    x = np.stack([s["final"]["x"], s["final"]["y"]], -1)
    return {"wall": float(s["loop_wall_time_s"]), "steps": int(s["steps"]), "sim": float(s["sim_time_s"]),
            "missed": int(s["missed_deadlines"]), "late": int(s["late_couples"]),
            "startup": resumed[0] - t0 if resumed else None, "x": x}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=1, help="runs of each way (medians reported)")
    ap.add_argument("--only", default="abcdef", help="the ways to run, e.g. 'c' or 'a,c' ((a) always runs)")
    args = ap.parse_args()
    paper = default_params_file()
    wall_clock = Path(tempfile.mkdtemp()) / "wall_clock.yaml"
    data = yaml.safe_load(paper.read_text())
    data["rod_simulator"]["ros__parameters"]["lockstep"] = False
    wall_clock.write_text(yaml.safe_dump(data))
    ways = {
        "(a) core only": core_only,
        "(b) in-process, lock-step": lambda: graph(paper, "--in-process"),
        "(c) processes, lock-step": lambda: graph(paper),
        "(d) processes, wall clock": lambda: graph(wall_clock),
        "(e) composed, lock-step": lambda: graph(paper, *COMPOSE),
        "(f) composed, wall clock": lambda: graph(wall_clock, *COMPOSE),
    }
    ways = {name: run for name, run in ways.items() if name[1] == "a" or name[1] in args.only}
    print(f"python {sys.version.split()[0]}, cores {os.cpu_count()}, paper scenario (N = {PAPER.rod.n_elements}, "
          f"control period {(PAPER.loop.control_period or 0.0) * 1e3:g} ms), {args.repeat} run(s) each, "
          f"load average at start {os.getloadavg()[0]:.2f}")
    core_only()  # (untimed: numba's cache loaded, as the simulator does before its first step)
    results: dict[str, list[dict[str, Any]]] = {name: [] for name in ways}
    for _ in range(args.repeat):
        for name, run in ways.items():
            results[name].append(run())
    core_ms = statistics.median(r["wall"] / r["steps"] for r in results["(a) core only"]) * 1e3  # (never fails)
    core_x = results["(a) core only"][0]["x"]
    print(f"{'':28s} {'ms/step':>8s} {'RTF':>6s} {'x core':>7s} {'missed':>6s} {'late':>5s} {'start-up s':>10s}  steps")
    for name, all_runs in results.items():
        runs = [r for r in all_runs if "error" not in r]
        for r in all_runs:
            if "error" in r:
                print(f"{name:28s} failed: {r['error']}")
        if not runs:
            continue
        ms = statistics.median(r["wall"] / r["steps"] for r in runs) * 1e3
        rtf = statistics.median(r["sim"] / r["wall"] for r in runs)
        ups = [r["startup"] for r in runs if r["startup"] is not None]
        startup = f"{statistics.median(ups):10.2f}" if ups else f"{'-':>10s}"
        print(f"{name:28s} {ms:8.2f} {rtf:6.2f} {ms / core_ms:7.2f} {max(r['missed'] for r in runs):6d} "
              f"{max(r['late'] for r in runs):5d} {startup}  {runs[0]['steps']}")
        if "lock-step" in name:
            same = all(np.array_equal(r["x"], core_x) for r in runs)
            print(f"{'':28s} final state equal to (a) bit for bit: {same}")
        elif "wall clock" in name:
            each = ", ".join("{missed}/{late}/{steps}".format(**r) for r in runs)
            print(f"{'':28s} runs (missed / late / steps): {each}")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
