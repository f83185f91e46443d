"""Benchmark: the closed loop with and without ROS 2 middleware, at the same control period.

For the paper scenario (packaged parameters) at a 1 kHz control rate in simulated time
(control period = integrator step = 1 ms), over the same number of control cycles:

  (a) core only: LoopSession + sensing + feedback in one Python loop (no ROS);
  (b) the ROS graph with all nodes in one process on one executor (`contgrasp-launch --in-process`);
  (c) the ROS graph as separate processes (`contgrasp-launch`), lock-step;

(b) with the single-threaded executor and with rclpy's experimental EventsExecutor (in separate
processes the EventsExecutor did not serve the simulator's pause service nor stop on SIGINT in
our trials, so node processes always use the single-threaded executor). Prints
control cycles per wall second and the overhead ratios (b)/(a), (c)/(a). Wall times of (b) and
(c) are the launcher's own measurement from the simulator's first state to its last (graph
start-up and discovery excluded), so all three time the same cycles.

Usage: .venv/bin/python benchmarks/ros_loop.py [--duration 0.5 --n-elements 50]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from contgrasp_core.rod.session import run_sampled
from contgrasp_core.scenario import Scenario
from contgrasp_ros.launcher import default_params_file, load_params


def core_only(params: dict) -> tuple[float, int]:
    t0 = time.perf_counter()
    session = run_sampled(Scenario.from_ros_parameters(params))
    return time.perf_counter() - t0, session.k


def graph(params_file: Path, *extra: str) -> tuple[float, int, int]:
    exe = Path(sys.executable).parent / "contgrasp-launch"
    out = subprocess.run([str(exe), "--json", "--params", str(params_file), *extra], capture_output=True, text=True, timeout=3600)
    if out.returncode != 0:
        raise SystemExit(f"launch failed: {out.stderr[-2000:]}")
    s = json.loads(out.stdout)
    return float(s["loop_wall_time_s"]), int(s["steps"]), int(s["missed_deadlines"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=0.5, help="simulated seconds (default 0.5 = 500 cycles)")
    ap.add_argument("--n-elements", type=int, default=50)
    args = ap.parse_args()
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = args.n_elements
    sim = data["rod_simulator"]["ros__parameters"]
    sim.update(duration=args.duration, control_period=0.001, dt=0.0, min_time=1e5)  # no early settle: fixed cycles
    data["grasp_quality"]["ros__parameters"]["rate_hz"] = 20.0
    tmp = Path(tempfile.mkdtemp()) / "bench.yaml"
    tmp.write_text(yaml.safe_dump(data))
    params = load_params(tmp)
    print(f"python {sys.version.split()[0]}, cores {os.cpu_count()}, N = {args.n_elements}, control 1 kHz (sim), "
          f"{args.duration:g} s simulated, load average {os.getloadavg()[0]:.2f}")
    a, ka = core_only(params)
    print(f"(a) core only                  : {a:7.2f} s  {ka / a:8.1f} cycles/s", flush=True)
    runs = (("(b) in-process [single]", ("--in-process", "--executor", "single")),
            ("(b) in-process [events]", ("--in-process", "--executor", "events")),
            ("(c) processes  [single]", ()))
    ratio_c = None
    for label, extra in runs:
        w, k, missed = graph(tmp, *extra)
        assert k == ka, f"{label} ran {k} cycles, core {ka}"
        print(f"{label}    : {w:7.2f} s  {k / w:8.1f} cycles/s  ratio to (a) {w / a:5.2f}  missed {missed}", flush=True)
        if label.startswith("(c)"):
            ratio_c = w / a
    print(f"target (c)/(a) <= 2 at 1 kHz: (c)/(a) = {ratio_c:.2f} -> {'met' if ratio_c <= 2 else 'NOT met'}")


if __name__ == "__main__":
    main()
