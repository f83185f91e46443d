"""Soak test: the launcher's process graph run back to back for a long time, with injected faults.

Launcher runs (``contgrasp-launch --respawn 1000 --bag ...``), each with a random object and base
pose, follow each other until ``--wall-time`` is used up; each lasts ``--run-time`` s and ends with
SIGINT. Meanwhile random node processes get SIGKILL (mean interval ``--kill-period``; the simulator
with probability ``--sim-fraction``) and the RSS of every process is sampled. Judged per run:
every kill recovered, the rod-state steps without gaps or repeats, missed deadlines, the
recorder's counts; per process, RSS growth beyond 3 standard errors of its slope (plotted to
``--figure``). Setup, criteria and results: docs/RELIABILITY.md, "Soak test".

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_LOG_DIR=/tmp/rl_soak AMENT_PREFIX_PATH=.venv \
        .venv/bin/python benchmarks/soak.py --wall-time 1860 --nodes 100 --domain-id 163
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from contgrasp_ros.plumbing import topics  # noqa: E402
from contgrasp_ros.launcher.launch_handle import LaunchHandle  # noqa: E402
from contgrasp_ros.launcher.cli import default_params_file  # noqa: E402

SIM = "rod_simulator"
KILLABLE = ("boundary_sensor", "grasp_controller", "grasp_quality")
RECORDER = "mcap_recorder"
ROLES = ("launcher", RECORDER, SIM, *KILLABLE)
SHORT = {"launcher": "launch", RECORDER: "rec", SIM: "sim", "boundary_sensor": "sens", "grasp_controller": "ctrl",
         "grasp_quality": "qual"}
COUPLE = topics.COUPLE
OUTPUT_TOPIC = {SIM: topics.ROD_STATE, "boundary_sensor": topics.CONTACT,
                "grasp_controller": topics.COUPLE, "grasp_quality": topics.QUALITY}
ARM_LENGTH = 0.20
ARM_RADIUS = 0.01  # radius at the base [m] (default.yaml)
RUNNING = r"graph connected; the simulator is running"


# --------------------------------------------------------------------------- scenario
def random_scenario(rng: random.Random) -> dict[str, Any]:
    """A random object and base pose: the object 2-3 cm in size, its centre 6-12 cm from the base,
    in front of it (positive along the base heading) and on its left (the side the arm curls to,
    as in the paper scenario) with at least 1 cm clearance from the straight initial arm."""
    kind = rng.choice(("circle", "ellipse", "deformed_circle"))
    if kind == "circle":
        size = rng.uniform(0.020, 0.030)
        extent, r_obj = size, size
    elif kind == "ellipse":
        a, b = rng.uniform(0.020, 0.030), rng.uniform(0.020, 0.030)
        extent, r_obj = max(a, b), math.sqrt(a * b)
    else:
        size = rng.uniform(0.020, 0.027)
        amplitude, lobes = rng.uniform(0.03, 0.10), rng.randint(2, 5)
        extent, r_obj = size * (1 + amplitude), size
    while True:  # centre in the base frame: u along the heading, v to the left
        u, v = rng.uniform(0.02, 0.11), rng.uniform(extent + ARM_RADIUS + 0.01, 0.11)
        if 0.06 <= math.hypot(u, v) <= 0.12:
            break
    bx, by, ba = rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-math.pi, math.pi)
    cx, cy = bx + u * math.cos(ba) - v * math.sin(ba), by + u * math.sin(ba) + v * math.cos(ba)
    angle = 0.0
    if kind == "circle":
        params = [size]
    elif kind == "ellipse":
        params, angle = [a, b], rng.uniform(-math.pi, math.pi)
    else:
        params = [size, amplitude, float(lobes), rng.uniform(-math.pi, math.pi)]
    shape = "deformed" if kind == "deformed_circle" else kind
    return {"object": f"{shape}:{','.join(f'{p:.5g}' for p in params)}", "object_angle": round(angle, 5),
            "object_kind": kind, "base": [round(bx, 5), round(by, 5), round(ba, 5)],
            "object_radius": round(r_obj, 5), "centre": [round(cx, 5), round(cy, 5)]}


def write_params(path: Path, scenario: dict[str, Any], n_elements: int, couple_timeout: float, fallback: str) -> None:
    data = yaml.safe_load(default_params_file().read_text())
    common = data["/**"]["ros__parameters"]
    common.update(n_elements=n_elements, base_x=scenario["base"][0], base_y=scenario["base"][1], base_angle=scenario["base"][2])
    data["rod_simulator"]["ros__parameters"].update(
        object=scenario["object"], object_center=scenario["centre"], object_angle=scenario["object_angle"],
        duration=1e5, min_time=1e5,  # never finished or settled within a run: it lasts until our SIGINT
        couple_timeout=couple_timeout, timeout_fallback=fallback,
    )
    data["grasp_controller"]["ros__parameters"]["object_radius"] = scenario["object_radius"]
    data["grasp_quality"]["ros__parameters"].update(reference_x=scenario["centre"][0], reference_y=scenario["centre"][1])
    path.write_text(yaml.safe_dump(data, sort_keys=False))


# --------------------------------------------------------------------------- processes
def rss_mb(pid: int) -> float | None:
    """Resident set size of a live process [MB]; None for a gone (or zombie) process."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


class RssLog:
    """RSS series per process (run, role, pid): (seconds since the soak started, MB)."""

    def __init__(self, t0: float) -> None:
        self.t0 = t0
        self.series: dict[tuple[int, str, int], list[tuple[float, float]]] = {}

    def sample(self, run: int, pids: dict[str, int]) -> None:
        now = time.monotonic() - self.t0
        for role, pid in pids.items():
            mb = rss_mb(pid)
            if mb is not None:
                self.series.setdefault((run, role, pid), []).append((round(now, 2), round(mb, 2)))


# --------------------------------------------------------------------------- one run
def run_once(i: int, args: argparse.Namespace, rng: random.Random, env: dict[str, str], rss: RssLog, run_time: float,
             stop: dict[str, bool]) -> dict[str, Any]:
    run_dir = args.out / f"run_{i:02d}"
    run_dir.mkdir(parents=True, exist_ok=True)
    scenario = random_scenario(rng)
    params = run_dir / "params.yaml"
    write_params(params, scenario, args.nodes, args.couple_timeout, args.fallback)
    bag = run_dir / "bag"
    rec: dict[str, Any] = {"run": i, **scenario, "bag_path": str(bag), "planned_run_time_s": run_time,
                           "kills": [], "launcher_pid": None}
    wall0 = time.monotonic()
    split = ["--max-bag-duration", str(args.max_bag_duration)] if args.max_bag_duration else []
    launch = LaunchHandle("--params", str(params), "--bag", str(bag), *split, "--respawn", "1000", "--domain-id", str(args.domain_id),
                          "--timeout", str(run_time + 900), env=env)
    rec["launcher_pid"] = launch.proc.pid
    interrupted_by_us = False
    try:
        try:
            launch.wait_for(RUNNING, timeout=args.start_timeout)
            rec["startup_s"] = round(time.monotonic() - wall0, 1)
        except AssertionError as exc:
            rec["startup_error"] = str(exc).splitlines()[0]
        t_start = time.monotonic()
        t_end = t_start + run_time
        next_kill = t_start + rng.expovariate(1.0 / args.kill_period)
        next_sample = t_start
        last_killed: dict[str, int] = {}
        while "startup_error" not in rec and launch.proc.poll() is None:
            now = time.monotonic()
            if now >= t_end or stop["flag"]:
                break
            if now >= next_sample:
                rss.sample(i, {"launcher": launch.proc.pid, **launch.pids})
                next_sample += args.sample_period
            if now >= next_kill:
                if now > t_end - args.quiet_tail:
                    next_kill = math.inf
                else:
                    name = SIM if rng.random() < args.sim_fraction else rng.choice(KILLABLE)
                    pid = launch.pids.get(name)
                    if pid is None or pid == last_killed.get(name) or not alive(pid):
                        next_kill = now + 1.0  # its replacement is not started yet: try again soon
                    else:
                        os.kill(pid, signal.SIGKILL)
                        last_killed[name] = pid
                        rec["kills"].append({"node": name, "pid": pid, "t_run_s": round(now - t_start, 2), "wall_ns": time.time_ns()})
                        log(f"  run {i}: t = {now - t_start:6.1f} s  SIGKILL {name} (pid {pid})")
                        next_kill = now + rng.expovariate(1.0 / args.kill_period)
            time.sleep(0.1)
        if launch.proc.poll() is None:
            interrupted_by_us = True
            launch.proc.send_signal(signal.SIGINT)
        rec["loop_wall_s"] = round(time.monotonic() - t_start, 1)
        try:
            code, summary = launch.result(timeout=240)
        except Exception as exc:  # noqa: BLE001 - a launcher that hangs or prints no JSON is a result too
            code, summary = launch.proc.poll(), {"error": f"no summary: {type(exc).__name__}: {exc}"}
    finally:
        if launch.proc.poll() is None:  # (an exception above): stop the launcher cleanly, it stops its nodes
            launch.proc.send_signal(signal.SIGINT)
            try:
                launch.proc.wait(timeout=90)
            except subprocess.TimeoutExpired:
                pass
        launch.close()
        (run_dir / "launcher.log").write_text("".join(launch.lines))
    rec["wall_s"] = round(time.monotonic() - wall0, 1)
    rec["interrupted_by_us"] = interrupted_by_us
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=1))
    rec["exit_code"] = code
    rec["error"] = summary.get("error")
    rec["restarts"] = summary.get("restarts", {})
    rec["faults"] = summary.get("faults", [])
    rec["exit_codes"] = summary.get("exit_codes", {})
    rec["steps_last_sim"] = summary.get("steps")
    rec["sim_time_last_sim_s"] = summary.get("sim_time_s")
    rec["missed_deadlines_summary"] = summary.get("missed_deadlines")
    b = summary.get("bag") or {}
    rec["bag"] = {k: b.get(k) for k in ("received", "written", "lost_in_transport", "decimated", "messages", "size_bytes", "error")}
    rec["left_running"] = [n for n, p in (summary.get("pids") or {}).items() if alive(p)]
    rec["restart_lines"] = sum("restarting it" in line for line in launch.lines)
    rec["from_the_past_warnings"] = sum("from the past" in line for line in launch.lines)
    rec.update(check_recording(bag, rec["kills"]))
    ended_ok = (interrupted_by_us and code == 130 and rec["error"] == "interrupted") or (not interrupted_by_us and code == 0)
    rec["ended_ok"] = ended_ok
    err = rec["error"] or ""
    rec["end"] = ("interrupted" if ended_ok and interrupted_by_us else "finished" if ended_ok
                  else "diverged" if err.startswith("simulator failed") else "error")
    if m := re.search(r"t = ([0-9.eE+-]+) s", err):
        rec["fail_sim_time_s"] = float(m.group(1))
    derive(rec)
    return rec


def derive(rec: dict[str, Any]) -> None:
    """The run's fault accounting from its kills, the launcher's restarts and the recording checks."""
    kills = defaultdict(int)
    for k in rec["kills"]:
        kills[k["node"]] += 1
    rec["kills_per_node"] = dict(kills)
    rec["restarts_match_kills"] = all(rec["restarts"].get(n, 0) == kills.get(n, 0) for n in (SIM, *KILLABLE))
    rec["faults_recovered"] = sum(1 for k in rec["kills"] if k.get("resumed"))
    rec["all_recovered"] = bool(rec["ended_ok"] and rec["restarts_match_kills"] and rec["faults_recovered"] == len(rec["kills"]))
    rec["recovery_list"] = [k["recovery_s"] for k in rec["kills"] if k.get("recovery_s") is not None]


def check_recording(bag: Path, kills: list[dict[str, Any]]) -> dict[str, Any]:
    """Step contiguity per simulator segment, missed deadlines over the simulator incarnations and
    the resumption of each killed node's output, from the finished recording."""
    from contgrasp_ros.bag import BagError
    from contgrasp_ros.bag.reader import iter_decoded, iter_raw, open_recording

    out: dict[str, Any] = {}
    try:
        rec = open_recording(bag)
        out["bag_files"] = len(rec.files)
        states = [(raw.log_time_ns, m.step) for raw, m in iter_decoded(rec, [topics.ROD_STATE])]
        steps = [s for _, s in states]
        missed_total, missed_current, last = 0, 0, -1
        for _, m in iter_decoded(rec, [topics.DIAGNOSTICS]):
            for st in m.status:
                if st.name != SIM:
                    continue
                v = {kv.key: kv.value for kv in st.values}
                try:
                    n = int(v.get("missed_deadlines", "0"))
                except ValueError:
                    continue
                if n < last:  # a new simulator: its count starts again
                    missed_total += missed_current
                    missed_current = 0
                missed_current, last = max(missed_current, n), n
        out["missed_deadlines_total"] = missed_total + missed_current
        # (topic -> [(log_ns, sequence)]) of the killed nodes' outputs
        seqs: dict[str, list[tuple[int, int]]] = defaultdict(list)
        for m in iter_raw(rec, sorted({OUTPUT_TOPIC[k["node"]] for k in kills} | {COUPLE})):
            seqs[m.topic].append((m.log_time_ns, m.sequence))
    except BagError as exc:
        return {"recording_error": str(exc), "steps_contiguous": False}
    segments: list[list[int]] = []
    for s in steps:
        if not segments or s == 0 or s <= segments[-1][-1]:
            segments.append([s])
        else:
            segments[-1].append(s)
    out["segments"] = [[seg[0], seg[-1], len(seg)] for seg in segments]
    out["steps_contiguous"] = bool(segments) and all(seg == list(range(len(seg))) for seg in segments)
    out["steps_recorded"] = len(steps)
    couples = [log_ns for log_ns, _ in seqs.get(COUPLE, [])]
    for k in kills:
        k["states_after"] = sum(1 for log_ns, _ in states if log_ns > k["wall_ns"])  # rod states recorded after the kill
        series = seqs.get(OUTPUT_TOPIC[k["node"]], [])
        k["resumed"], k["output_s"], k["loop_closed_s"], k["recovery_s"] = False, None, None, None
        prev, first_ns = None, None
        for log_ns, seq in series:
            # the first message of a new publisher after the kill: its sequence starts over (a publisher's own
            # sequence numbers strictly increase, so seq <= the previous one means a new publisher)
            if log_ns > k["wall_ns"] and (prev is None or seq <= prev):
                first_ns = log_ns
                break
            prev = seq
        if first_ns is None:
            continue
        k["output_s"] = round((first_ns - k["wall_ns"]) * 1e-9, 2)
        if k["node"] == "grasp_quality":  # not in the loop: its output coming back is its recovery
            k["resumed"], k["recovery_s"] = True, k["output_s"]
            continue
        # the loop is closed again when a controller's couple follows the replacement's first output
        # (a sensor or controller that drops the new states publishes no couple; the simulator
        # then steps on its timeout fallback)
        nxt = next((c for c in couples if c >= first_ns), None)
        if nxt is not None:
            k["loop_closed_s"] = round((nxt - k["wall_ns"]) * 1e-9, 2)
            k["resumed"], k["recovery_s"] = True, k["loop_closed_s"]
    # a kill that comes while the loop is still open after an earlier fault finds its node without
    # input (no rod state or contact to answer): it cannot show a recovery of its own
    for i, k in enumerate(kills):
        if k["resumed"]:
            continue
        for e in kills[:i]:
            open_until = e["wall_ns"] + int(e["recovery_s"] * 1e9) if e.get("recovery_s") is not None else math.inf
            if e["node"] != "grasp_quality" and e["wall_ns"] < k["wall_ns"] < open_until:
                k["masked_by"] = f"{e['node']} killed at t = {e['t_run_s']} s"
                break
    return out


def recheck_diverged(r: dict[str, Any], args: argparse.Namespace, env: dict[str, str]) -> dict[str, Any]:
    """Run a diverged run's scenario again without faults (no recording) to a little past the
    simulated time where it failed: does it diverge without the faults too?"""
    t_fail = r["fail_sim_time_s"]
    cmd = [str(Path(sys.executable).parent / "contgrasp-launch"), "--json", "--no-record", "--params",
           str(args.out / f"run_{r['run']:02d}" / "params.yaml"), "--domain-id", str(args.domain_id),
           "--duration", f"{t_fail + 0.05:.4f}", "--timeout", str(args.recheck_timeout)]
    t0 = time.monotonic()
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=args.recheck_timeout + 120)
        out = json.loads(proc.stdout)
    except (subprocess.TimeoutExpired, json.JSONDecodeError) as exc:
        return {"error": f"{type(exc).__name__}", "wall_s": round(time.monotonic() - t0, 1)}
    err = out.get("error") or ""
    return {"diverged_without_faults": err.startswith("simulator failed"), "error": out.get("error"),
            "sim_time_s": out.get("sim_time_s"), "max_penetration": out.get("max_penetration"),
            "wall_s": round(time.monotonic() - t0, 1)}


# --------------------------------------------------------------------------- RSS analysis
def rss_stats(series: list[tuple[float, float]], warmup: float = 15.0) -> dict[str, Any]:
    """Start (first sample ``warmup`` s after the first one: a (re)started node is still importing
    before that), end, max, and the fit over the second half of the sampled lifetime."""
    t = np.array([p[0] for p in series])
    r = np.array([p[1] for p in series])
    life = float(t[-1] - t[0])
    warm = t >= t[0] + warmup
    start = float(r[warm][0]) if warm.any() else float(r[-1])
    out: dict[str, Any] = {"lifetime_s": round(life, 1), "start_mb": start, "end_mb": float(r[-1]), "max_mb": float(r.max()), "samples": len(r)}
    half = t >= t[0] + life / 2
    if half.sum() >= 5 and np.ptp(t[half]) > 0:
        th, rh = t[half], r[half]
        slope, icpt = np.polyfit(th, rh, 1)
        resid = rh - (slope * th + icpt)
        noise = float(np.sqrt((resid**2).sum() / max(len(rh) - 2, 1)))
        se = noise / float(np.sqrt(((th - th.mean()) ** 2).sum()))
        out.update(rise_2nd_half_mb=round(float(rh[-1] - rh[0]), 2), slope_mb_h=round(float(slope) * 3600, 2), slope_se_mb_h=round(se * 3600, 2), resid_std_mb=round(noise, 3),
                   growth=bool(slope > 3 * se and slope > 0))
    return out


def rss_summary(rss: RssLog, min_lifetime: float, warmup: float = 15.0) -> dict[str, Any]:
    per_role: dict[str, dict[str, Any]] = {}
    procs: list[dict[str, Any]] = []
    for (run, role, pid), series in rss.series.items():
        st = rss_stats(series, warmup)
        procs.append({"run": run, "role": role, "pid": pid, **st})
    for role in ROLES:
        mine = [p for p in procs if p["role"] == role]
        long = [p for p in mine if p["lifetime_s"] >= min_lifetime and "slope_mb_h" in p]
        if not mine:
            continue
        d: dict[str, Any] = {"processes": len(mine), "long_lived": len(long), "max_mb_all": round(max(p["max_mb"] for p in mine), 1)}
        if long:
            def med(key: str, ps: list[dict[str, Any]] = long) -> float:
                return round(float(np.median([p[key] for p in ps])), 2)
            d.update(
                start_mb_median=med("start_mb"), end_mb_median=med("end_mb"), max_mb=round(max(p["max_mb"] for p in long), 1),
                end_minus_start_mb_median=round(float(np.median([p["end_mb"] - p["start_mb"] for p in long])), 2),
                slope_mb_h_median=med("slope_mb_h"), slope_mb_h_max=round(max(p["slope_mb_h"] for p in long), 2),
                slope_se_mb_h_median=med("slope_se_mb_h"), resid_std_mb_median=med("resid_std_mb"),
                slope_mb_h_spread=round(float(np.std([p["slope_mb_h"] for p in long])), 2),
                rise_2nd_half_mb_median=med("rise_2nd_half_mb"),
                lifetime_s_median=med("lifetime_s"), growing=sum(p["growth"] for p in long),
            )
        per_role[role] = d
    return {"per_role": per_role, "processes": procs}


def plot_rss(rss: RssLog, runs: list[dict[str, Any]], path: Path, title: str, warmup: float = 15.0) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True)
    for ax, role in zip(axes.flat, ROLES, strict=True):
        for (_run, r, _pid), series in sorted(rss.series.items()):
            if r != role or not series:
                continue
            t = np.array([p[0] for p in series]) / 60.0
            ax.plot(t, [p[1] for p in series], lw=0.9, marker="." if len(series) < 3 else None)
        for run in runs:
            if run.get("t_start_soak_s") is not None:
                ax.axvline(run["t_start_soak_s"] / 60.0, color="0.8", lw=0.6, zorder=0)
        warm = [p[1] for (_r, r, _p), ser in rss.series.items() if r == role for p in ser if p[0] >= ser[0][0] + warmup]
        if warm:  # the axis spans the warmed-up samples; a (re)started node's first seconds lie below it
            ax.set_ylim(min(warm) - 1.0, max(warm) + 1.0)
        ax.set_title(role, fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("RSS [MB]")
    for ax in axes[-1]:
        ax.set_xlabel("soak time [min]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- report
def log(msg: str) -> None:
    print(msg, flush=True)


def fmt_kills(d: dict[str, int]) -> str:
    return " ".join(f"{SHORT[n]}{d[n]}" for n in (SIM, *KILLABLE) if d.get(n)) or "-"


def run_row(r: dict[str, Any]) -> str:
    b = r.get("bag") or {}
    obj = r["object_kind"][:4] if r["object_kind"] != "deformed_circle" else "defc"
    base = r["base"]
    seg = r.get("segments") or []
    rec = r.get("recovery_list") or []
    return (f"{r['run']:>3} {obj:<4} [{base[0]:+.3f},{base[1]:+.3f},{base[2]:+.2f}] {r['exit_code']!s:>4} {r['end'][:5]:<5} "
            f"{r.get('loop_wall_s', 0):>6.0f} {fmt_kills(r['kills_per_node']):<22} {fmt_kills(r['restarts']):<22} "
            f"{r['faults_recovered']:>2}/{len(r['kills']):<2} {('yes' if r['all_recovered'] else 'NO'):<4} "
            f"{r.get('missed_deadlines_total', '?')!s:>5} {b.get('received')!s:>8} {b.get('written')!s:>8} "
            f"{b.get('lost_in_transport')!s:>4} {b.get('decimated')!s:>3} {len(seg):>3} "
            f"{('yes' if r.get('steps_contiguous') else 'NO'):<4} {max(rec) if rec else 0:>6.1f} {r.get('from_the_past_warnings', 0):>5}")


HEADER = (f"{'run':>3} {'obj':<4} {'base [x,y,angle]':<24} {'exit':>4} {'end':<5} {'loop_s':>6} {'kills':<22} {'restarts':<22} "
          f"{'recov':>5} {'ok':<4} {'missd':>5} {'received':>8} {'written':>8} {'lost':>4} {'dec':>3} {'seg':>3} "
          f"{'cont':<4} {'maxrec':>6} {'stale':>5}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--wall-time", type=float, default=1800.0, help="total wall time [s] (default 1800)")
    p.add_argument("--run-time", type=float, default=300.0, help="wall time of each launcher run's loop [s] (default 300)")
    p.add_argument("--kill-period", type=float, default=45.0, help="mean time between injected faults [s] (default 45)")
    p.add_argument("--sim-fraction", type=float, default=0.2, help="share of faults that kill the simulator (default 0.2)")
    p.add_argument("--quiet-tail", type=float, default=15.0, help="no fault in the last SECONDS of a run (default 15)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: from the clock; printed)")
    p.add_argument("--out", type=Path, default=Path("/tmp/contgrasp_soak"), help="bags, logs, parameter files (default /tmp/contgrasp_soak)")
    p.add_argument("--domain-id", type=int, default=163, help="ROS_DOMAIN_ID of the graph (default 163)")
    p.add_argument("--nodes", type=int, default=100, help="rod elements (default 100 = the paper)")
    p.add_argument("--couple-timeout", type=float, default=0.5, help="the simulator's lock-step couple_timeout [s] (default 0.5)")
    p.add_argument("--fallback", choices=("hold", "zero"), default="hold", help="the simulator's timeout_fallback (default hold)")
    p.add_argument("--recheck-diverged", type=int, default=3, metavar="N",
                   help="after the soak, rerun up to N diverged scenarios without faults (default 3)")
    p.add_argument("--recheck-timeout", type=float, default=300.0, help="wall-clock limit of one recheck [s] (default 300)")
    p.add_argument("--sample-period", type=float, default=3.0, help="RSS sampling period [s] (default 3)")
    p.add_argument("--min-lifetime", type=float, default=None, help="processes judged for RSS growth live at least this long [s] "
                   "(default 0.4 x --run-time)")
    p.add_argument("--warmup", type=float, default=15.0, help="RSS 'start' is the first sample this long after a process's first [s]")
    p.add_argument("--from-report", type=Path, default=None, metavar="REPORT",
                   help="run nothing: recompute the RSS statistics of a soak's JSON report, print its tables, redraw the figure")
    p.add_argument("--start-timeout", type=float, default=180.0, help="wait this long for the loop to start [s] (default 180)")
    p.add_argument("--report", type=Path, default=None, help="JSON report (default OUT/soak_report.json)")
    p.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "soak_rss.png", help="RSS plot (default docs/figures/soak_rss.png)")
    p.add_argument("--max-bag-duration", type=float, default=0.0, metavar="SECONDS",
                   help="split each run's bag into files of SECONDS (contgrasp-launch --max-bag-duration; default 0: one file)")
    p.add_argument("--delete-bags", action="store_true", help="delete a run's bag once its checks passed (default: keep every bag)")
    args = p.parse_args(argv)
    if args.seed is None:
        args.seed = int(time.time()) % 100000
    args.min_lifetime = 0.4 * args.run_time if args.min_lifetime is None else args.min_lifetime
    report_path = args.report or args.out / "soak_report.json"
    if args.from_report is not None:
        return reanalyse(args)
    args.out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("ROS_LOG_DIR", "/tmp/rl_soak")
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    rng = random.Random(args.seed)
    command = " ".join([Path(sys.argv[0]).as_posix(), *(sys.argv[1:] if argv is None else argv)])
    meta = {"command": command, "seed": args.seed, "date": dt.datetime.now().astimezone().isoformat(timespec="seconds"),
            "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                        "load_avg_start": os.getloadavg()},
            "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}}
    log(f"soak: seed {args.seed}, domain {args.domain_id}, N = {args.nodes}, wall {args.wall_time:.0f} s, run {args.run_time:.0f} s, "
        f"mean kill period {args.kill_period:.0f} s, out {args.out}")
    t0 = time.monotonic()
    rss = RssLog(t0)
    runs: list[dict[str, Any]] = []
    overhead = 45.0  # start-up + shut-down + checks of one run [s]; measured as runs go
    stop = {"flag": False}

    def on_term(signum: int, _frame: Any) -> None:
        stop["flag"] = True

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)  # end the current run cleanly (the launcher stops its nodes), then report
    try:
        while not stop["flag"]:
            remaining = args.wall_time - (time.monotonic() - t0)
            run_time = min(args.run_time, remaining - overhead)
            if run_time < min(args.run_time, max(30.0, 0.25 * args.run_time)):
                break
            i = len(runs)
            log(f"run {i}: loop {run_time:.0f} s (remaining wall time {remaining:.0f} s)")
            t_run = time.monotonic()
            r = run_once(i, args, rng, env, rss, run_time, stop)
            r["t_start_soak_s"] = round(t_run - t0, 1)
            overhead = max(overhead, r["wall_s"] - r.get("loop_wall_s", 0) + 5.0)
            runs.append(r)
            log(f"  {r['object']} at {r['centre']} base {r['base']}: exit {r['exit_code']}, error {r['error']!r}, "
                f"restarts {r['restarts']}, kills {r['kills_per_node']}, recovered {r['faults_recovered']}/{len(r['kills'])}, "
                f"steps contiguous {r.get('steps_contiguous')} ({len(r.get('segments') or [])} segments), bag {r['bag']}")
            if r.get("recording_error"):
                log(f"  recording: {r['recording_error']}")
            if r["left_running"]:
                log(f"  processes still alive after the run: {r['left_running']}")
            if args.delete_bags and r["all_recovered"] and r.get("steps_contiguous"):
                shutil.rmtree(r["bag_path"], ignore_errors=True)
                r["bag_deleted"] = True
            write_report(report_path, meta, runs, rss, args)
        diverged = [r for r in runs if r["end"] == "diverged" and "fail_sim_time_s" in r]
        for r in diverged[: args.recheck_diverged]:
            if stop["flag"]:
                break
            log(f"recheck: run {r['run']}'s scenario without faults to t = {r['fail_sim_time_s'] + 0.05:.3f} s")
            r["recheck"] = recheck_diverged(r, args, env)
            log(f"  {r['recheck']}")
    finally:
        if runs:
            write_report(report_path, meta, runs, rss, args)
    rep = json.loads(report_path.read_text()) if runs else {}
    print_tables(rep)
    if runs:
        title = (f"soak: {len(runs)} runs, N = {args.nodes}, {args.wall_time / 60:.0f} min, faults every {args.kill_period:.0f} s "
                 f"on average (seed {args.seed}); grey lines: run starts; "
                 f"y axes span samples >= {args.warmup:.0f} s after a process started")
        plot_rss(rss, runs, args.figure, title, args.warmup)
        log(f"figure: {args.figure}\nreport: {report_path}")
    return 0


def _quantiles(xs: list[float]) -> dict[str, float] | None:
    if not xs:
        return None
    return {"n": len(xs), "median": round(float(np.median(xs)), 2), "max": round(float(max(xs)), 2)}


def write_report(path: Path, meta: dict[str, Any], runs: list[dict[str, Any]], rss: RssLog, args: argparse.Namespace) -> None:
    summary = {**summarise(runs), "wall_s": round(time.monotonic() - rss.t0, 1), "load_avg_end": os.getloadavg()}
    rs = rss_summary(rss, args.min_lifetime, args.warmup)
    series = [{"run": k[0], "role": k[1], "pid": k[2], "samples": v} for k, v in rss.series.items()]
    path.write_text(json.dumps({**meta, "summary": summary, "rss": rs["per_role"], "rss_processes": rs["processes"],
                                "runs": runs, "rss_series": series}, indent=1, default=float))


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    kills = sum(len(r["kills"]) for r in runs)
    bags = [r["bag"] for r in runs]

    def total(key: str) -> int:
        return sum(int(b.get(key) or 0) for b in bags)

    rec = [x for r in runs for x in r.get("recovery_list", [])]
    summary = {
        "runs": len(runs),
        "runs_ended_ok": sum(r["ended_ok"] for r in runs),
        "runs_by_end": {e: sum(r["end"] == e for r in runs) for e in ("interrupted", "finished", "diverged", "error")},
        "diverged_rechecked": [{"run": r["run"], "fail_sim_time_s": r.get("fail_sim_time_s"),
                                "kills_before_end": len(r["kills"]), **r["recheck"]} for r in runs if "recheck" in r],
        "runs_all_recovered": sum(r["all_recovered"] for r in runs),
        "runs_steps_contiguous": sum(bool(r.get("steps_contiguous")) for r in runs),
        "faults_injected": kills,
        "faults_injected_per_node": {n: sum(r["kills_per_node"].get(n, 0) for r in runs) for n in (SIM, *KILLABLE)},
        "restarts_per_node": {n: sum(r["restarts"].get(n, 0) for r in runs) for n in (SIM, *KILLABLE)},
        "faults_recovered": sum(r["faults_recovered"] for r in runs),
        "recovery_s": {"median": float(np.median(rec)), "p90": float(np.percentile(rec, 90)), "max": float(max(rec))} if rec else None,
        "recovery_s_per_node": {n: _quantiles([k["recovery_s"] for r in runs for k in r["kills"] if k["node"] == n and k.get("recovery_s") is not None])
                                for n in (SIM, *KILLABLE)},
        "unrecovered_kills": [{"run": r["run"], **k} for r in runs for k in r["kills"] if not k.get("resumed")],
        "from_the_past_warnings": sum(r.get("from_the_past_warnings", 0) for r in runs),
        "received": total("received"), "written": total("written"), "lost_in_transport": total("lost_in_transport"),
        "decimated": total("decimated"),
        "missed_deadlines_total": sum(int(r.get("missed_deadlines_total") or 0) for r in runs),
        "loop_wall_s": round(sum(r.get("loop_wall_s", 0) for r in runs), 1),
        "steps_recorded": sum(int(r.get("steps_recorded") or 0) for r in runs),
    }
    return summary


def reanalyse(args: argparse.Namespace) -> int:
    rep = json.loads(args.from_report.read_text())
    settings = rep.get("settings", {})
    min_life = 0.4 * float(settings.get("run_time", args.run_time)) if "--min-lifetime" not in sys.argv else args.min_lifetime
    rss = RssLog(0.0)
    for s in rep["rss_series"]:
        rss.series[(s["run"], s["role"], s["pid"])] = [tuple(x) for x in s["samples"]]
    rs = rss_summary(rss, min_life, args.warmup)
    rep["rss"], rep["rss_processes"] = rs["per_role"], rs["processes"]
    for r in rep["runs"]:  # the recording checks again, where the bag is still there
        if Path(r["bag_path"]).exists() and all("wall_ns" in k for k in r["kills"]):
            r.update(check_recording(Path(r["bag_path"]), r["kills"]))
            derive(r)
    rep["summary"] = {**rep["summary"], **summarise(rep["runs"])}
    out = args.report or args.from_report
    out.write_text(json.dumps(rep, indent=1, default=float))
    print_tables(rep)
    s = rep["settings"]
    title = (f"soak: {len(rep['runs'])} runs, N = {s['nodes']}, {s['wall_time'] / 60:.0f} min, faults every {s['kill_period']:.0f} s "
             f"on average (seed {rep['seed']}); grey lines: run starts; "
             f"y axes span samples >= {args.warmup:.0f} s after a process started")
    plot_rss(rss, rep["runs"], args.figure, title, args.warmup)
    log(f"figure: {args.figure}\nreport: {out}")
    return 0


def print_tables(rep: dict[str, Any]) -> None:
    if not rep:
        log("no run completed")
        return
    log("\nper run (kills/restarts: sim/sens/ctrl/qual; recov = killed nodes whose output resumed; ok = all recovered and the run "
        "ended by our SIGINT; missd = missed deadlines over all simulators; seg = rod_state segments; cont = each 0..k; "
        "maxrec = slowest recovery [s]; stale = 'from the past' drop warnings)")
    log(HEADER)
    for r in rep["runs"]:
        log(run_row(r))
    s = rep["summary"]
    log(f"\nruns {s['runs']} {s['runs_by_end']} (ended as expected {s['runs_ended_ok']}, all faults recovered {s['runs_all_recovered']}, "
        f"steps contiguous {s['runs_steps_contiguous']}), loop time {s['loop_wall_s']:.0f} s")
    log(f"faults injected {s['faults_injected']} {s['faults_injected_per_node']}, recovered {s['faults_recovered']}, "
        f"launcher restarts {s['restarts_per_node']}, recovery time {s['recovery_s']}")
    log(f"recovery time per node (to the loop closed again; quality: to its output): {s['recovery_s_per_node']}")
    for k in s["unrecovered_kills"]:
        log(f"  not recovered: run {k['run']} {k['node']} killed at t = {k['t_run_s']} s (output resumed after {k.get('output_s')} s, {k.get('states_after')} rod states recorded after the kill"
            + (f"; the loop was still open after the {k['masked_by']})" if k.get("masked_by") else ")"))
    log(f"'from the past' drop warnings in the logs: {s['from_the_past_warnings']}")
    log(f"messages received {s['received']}, written {s['written']}, lost in transport {s['lost_in_transport']}, "
        f"decimated {s['decimated']}; missed deadlines {s['missed_deadlines_total']}; rod states recorded {s['steps_recorded']}")
    for d in s["diverged_rechecked"]:
        log(f"diverged run {d['run']} (t = {d['fail_sim_time_s']} s, {d['kills_before_end']} faults injected) rerun without faults: "
            f"diverged again {d.get('diverged_without_faults')} ({d.get('error')})")
    log("\nRSS per node type (long-lived processes; MB, medians; slope over the second half of each lifetime: median [max], "
        "spread = std across processes, se = its standard error from the residuals; rise = RSS change over the second half; "
        "growing = slope > 3 se)")
    log(f"{'role':<17} {'procs':>5} {'long':>4} {'start':>7} {'end':>7} {'max':>7} {'slope MB/h':>16} {'spread':>7} {'se MB/h':>8} "
        f"{'resid MB':>8} {'rise MB':>7} {'growing':>7}")
    for role, d in rep["rss"].items():
        if "start_mb_median" not in d:
            log(f"{role:<17} {d['processes']:>5} {d['long_lived']:>4}  (none long-lived; max {d['max_mb_all']} MB)")
            continue
        log(f"{role:<17} {d['processes']:>5} {d['long_lived']:>4} {d['start_mb_median']:>7.1f} {d['end_mb_median']:>7.1f} "
            f"{d['max_mb']:>7.1f} {d['slope_mb_h_median']:>7.1f} [{d['slope_mb_h_max']:>6.1f}] {d['slope_mb_h_spread']:>7.1f} "
            f"{d['slope_se_mb_h_median']:>8.1f} {d['resid_std_mb_median']:>8.2f} {d['rise_2nd_half_mb_median']:>7.2f} "
            f"{d['growing']:>3}/{d['long_lived']}")


if __name__ == "__main__":
    sys.exit(main())
