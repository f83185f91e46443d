"""Fault injection with real processes: nodes killed with SIGKILL mid-run, the launcher
interrupted. The graph degrades as documented (docs/RELIABILITY.md) and the recording stays
complete and readable up to the fault."""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy")

from conftest import fresh_domain_id  # noqa: E402

from contgrasp_ros.bag.reader import iter_decoded, open_recording  # noqa: E402
from contgrasp_ros.launcher.launch_handle import LaunchHandle  # noqa: E402
from contgrasp_ros.launcher.cli import default_params_file  # noqa: E402
from contgrasp_ros.recordings.recompute import step_gaps  # noqa: E402
from contgrasp_ros.recordings.run_data import load_run  # noqa: E402

BIN = Path(sys.executable).parent
NODES = ("rod_simulator", "boundary_sensor", "grasp_controller", "grasp_quality")


def fault_params(tmp_path: Path, duration: float = 1.5, timeout: float = 0.5, fallback: str = "hold", **sim_extra: float) -> Path:
    """The packaged scenario on a coarse rod (fast steps) with a short lock-step timeout.

    Twenty elements are not a converged discretisation of the grasp: the coarse arm swings
    about without settling and its 1 cm elements can press up to ~1 mm into the object (more
    after a fallback outage). These tests are about process faults, so the divergence limit on
    penetration is raised from the tip radius to 1 cm (the divergence stop has its own tests)."""
    sim_extra = {"max_penetration_limit": 0.01, **sim_extra}
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = 20
    sim = data["rod_simulator"]["ros__parameters"]
    sim.update(duration=duration, couple_timeout=timeout, timeout_fallback=fallback, marker_period=0.0,
               min_time=10.0, **sim_extra)  # never settles early
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def Launch(*args: str) -> LaunchHandle:  # noqa: N802 - reads like the class it returns
    return LaunchHandle("--domain-id", str(fresh_domain_id()), *args)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def recorded_steps(bag: Path) -> list[int]:
    """The recorded rod states' steps in the order they were published (as ``load_run`` reads
    them): a reader that matched the simulator's writer mid-send may receive step 0 after steps
    1-4 (seen once in CI), so the receive-time log order need not be the publication order."""
    msgs = iter_decoded(open_recording(bag), ["/contgrasp/rod_state"])
    return [m.step for _, m in sorted(msgs, key=lambda rm: rm[0].publish_time_ns)]


def killed_mid_run(launch: LaunchHandle, node: str) -> tuple[int, dict]:
    """Kill ``node`` once the loop runs (:func:`running`); the launcher's exit code and summary."""
    try:
        running(launch)
        launch.signal(node, signal.SIGKILL)
        return launch.result()
    finally:
        launch.close()


def running(launch: Launch) -> int:
    """Wait until the loop runs (the launcher resumed the simulator), then a little longer.

    The coarse rod steps at about real time on an idle machine, so the runs below last a few
    times longer in simulated time than this wait: a fault must land mid-run on a fast machine
    too (with 1 s here and a 0.4 s run, an idle machine finished the run before the kill)."""
    i = launch.wait_for(r"graph connected; the simulator is running")
    time.sleep(0.3)
    return i


@pytest.mark.heavy
def test_controller_and_sensor_killed_and_respawned_the_loop_resumes(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    launch = Launch("--params", str(fault_params(tmp_path, duration=2.0)), "--bag", str(bag), "--respawn", "2")
    try:
        running(launch)
        launch.signal("grasp_controller", signal.SIGKILL)
        i = launch.wait_for(r"'grasp_controller' exited with code -9; restarting it \(1/2\)")
        launch.wait_event("restarted", node="grasp_controller")
        launch.wait_for(r"couples are back", start=i)  # the loop closed again with the new controller
        launch.signal("boundary_sensor", signal.SIGKILL)
        launch.wait_for(r"'boundary_sensor' exited with code -9; restarting it \(1/2\)")
        code, out = launch.result()
    finally:
        launch.close()
    assert code == 0, "".join(launch.lines[-40:])
    assert out["restarts"] == {"grasp_controller": 1, "boundary_sensor": 1}
    assert out["simulator_state"] == "finished" and out["sim_time_s"] == pytest.approx(2.0)
    assert out["missed_deadlines"] >= 1  # the fallback covered the gap, then the loop resumed
    # one warning per outage (at most one per kill), and a note when the couples come back
    warned = sum("applying the 'hold' fallback" in line for line in launch.lines)
    assert 1 <= warned <= 2 and sum("couples are back" in line for line in launch.lines) == warned
    # the recorder kept everything: every step, and the states the simulator sent again once a
    # restarted node joined (each recorded twice in a row), which the analysis counts once
    steps = recorded_steps(bag)
    assert [k for i, k in enumerate(steps) if i == 0 or k != steps[i - 1]] == list(range(out["steps"] + 1))
    gaps = step_gaps(load_run(bag))
    assert gaps["contiguous"] and gaps["repeated_states"] == len(steps) - (out["steps"] + 1)
    assert out["bag"]["received"] == out["bag"]["written"]
    assert not any(alive(pid) for pid in out["pids"].values())
    # the events: the domain first, every start and restart with its pid, the exits, the end
    ev = launch.events
    assert ev[0]["event"] == "domain_id" and ev[0]["mode"] == "processes"
    assert ev[-1]["event"] == "finished" and ev[-1]["exit_code"] == 0 and ev[-1]["error"] is None
    assert launch.pids == out["pids"]  # each node's latest pid
    assert [(e["node"], e["exit_code"], e["action"]) for e in ev if e["event"] == "exited"] == [
        ("grasp_controller", -9, "restarted"), ("boundary_sensor", -9, "restarted")]
    assert sorted(e["node"] for e in ev if e["event"] == "restarted") == ["boundary_sensor", "grasp_controller"]
    assert [e["restart"] for e in ev if e["event"] == "resumed"] == [False]


@pytest.mark.heavy
def test_a_killed_container_is_restarted_as_one_process_and_the_loop_resumes(tmp_path: Path) -> None:
    """--compose: the process hosting the sensor and the controller is supervised as one, under
    its composed name: killed, it is restarted with both nodes and the loop closes again."""
    name = "boundary_sensor+grasp_controller"
    launch = Launch("--params", str(fault_params(tmp_path, duration=2.0)), "--no-record", "--respawn", "1",
                    "--compose", "boundary_sensor,grasp_controller")
    try:
        i = running(launch)
        launch.signal(name, signal.SIGKILL)
        launch.wait_for(rf"'{re.escape(name)}' exited with code -9; restarting it \(1/1\)", start=i)
        launch.wait_event("restarted", node=name)
        code, out = launch.result()
    finally:
        launch.close()
    assert code == 0, "".join(launch.lines[-40:])
    assert out["restarts"] == {name: 1} and out["exit_codes"][name] == 0
    assert out["simulator_state"] == "finished" and out["sim_time_s"] == pytest.approx(2.0)
    # both nodes came back and the loop closed again: after missing deadlines, or within the first
    # (a fast restart: the state re-sent to the new peer answered before the timeout; CI met it)
    assert any("couples are back" in line or "the loop closed again" in line for line in launch.lines), "".join(launch.lines[-40:])
    assert not any(alive(pid) for pid in out["pids"].values())


@pytest.mark.heavy
def test_a_dead_controller_without_respawn_degrades_to_the_fallback(tmp_path: Path) -> None:
    """(The `zero` fallback: holding the last couple open loop for the rest of the run can make
    the coarse rod's impact on the object fail a Newton step, which the simulator then reports
    as a failed run - correct, but not what this test is about. For the same reason the
    penetration limit is raised: with the couple zeroed at a random
    moment of the swing, the coarse rod's impact reached 1.07 mm in one of five runs; see
    fault_params.)"""
    bag = tmp_path / "bag"
    launch = Launch("--params", str(fault_params(tmp_path, duration=0.8, timeout=0.05, fallback="zero")), "--bag", str(bag))
    try:
        running(launch)
        launch.signal("grasp_controller", signal.SIGKILL)
        launch.wait_for(r"'grasp_controller' exited with code -9; the run continues without it")
        code, out = launch.result()
    finally:
        launch.close()
    assert out["simulator_state"] == "finished" and out["sim_time_s"] == pytest.approx(0.8), out.get("error")
    assert out["missed_deadlines"] > 0 and out["exit_codes"]["grasp_controller"] == -9
    assert {"node": "grasp_controller", "exit_code": -9, "action": "continued without it"} in out["faults"]
    assert sum("applying the 'zero' fallback" in line for line in launch.lines) == 1  # once per outage
    assert recorded_steps(bag) == list(range(out["steps"] + 1))
    assert code == 0 and "error" not in out


def zombie_shm_segments() -> set[str]:
    """Fast DDS shared-memory segments in /dev/shm whose lock no live process holds (what a
    killed participant leaves behind)."""
    import fcntl

    shm = Path("/dev/shm")
    found = set()
    for lock in shm.glob("fastrtps_*_el"):
        try:
            with open(lock, "ab") as fd:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(fd, fcntl.LOCK_UN)
        except BlockingIOError:
            continue  # held: in use
        except OSError:
            continue  # gone meanwhile
        found.add(lock.name)
    return found


@pytest.mark.heavy
def test_killed_simulator_stops_the_run_and_the_recording_is_complete(tmp_path: Path) -> None:
    """... and the killed node's shared-memory files do not stay behind in /dev/shm."""
    bag = tmp_path / "bag"
    zombies_before = zombie_shm_segments()
    launch = Launch("--params", str(fault_params(tmp_path, duration=100.0)), "--bag", str(bag))
    code, out = killed_mid_run(launch, "rod_simulator")
    assert code == 1 and out["error"] == "node 'rod_simulator' exited with code -9"
    assert not zombie_shm_segments() - zombies_before
    ended = [e for e in launch.events if e["event"] in ("exited", "finished")]
    assert [e["event"] for e in ended] == ["exited", "finished"]
    assert ended[0]["node"] == "rod_simulator" and ended[0]["action"] == "run ended" and ended[0]["exit_code"] == -9
    assert ended[1]["exit_code"] == 1 and ended[1]["error"] == out["error"]
    assert out["exit_codes"]["rod_simulator"] == -9
    # stopped cleanly (the message a string: pytest prints it whole, a crashed node's stacks with it)
    assert all(out["exit_codes"][n] == 0 for n in NODES[1:]), f"{out['exit_codes']}\n{''.join(launch.lines[-80:])}"
    assert out["exit_codes"]["mcap_recorder"] == 0
    steps = recorded_steps(bag)  # finalised, readable, every state the simulator published
    assert steps and steps == list(range(len(steps)))
    assert len(steps) >= out["steps"] + 1
    assert not any(alive(pid) for pid in out["pids"].values())


@pytest.mark.heavy
def test_interrupted_launcher_stops_everything_and_finalises_the_recording(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    launch = Launch("--params", str(fault_params(tmp_path, duration=100.0)), "--bag", str(bag))
    try:
        launch.wait_for(r"recording /contgrasp/quality")
        time.sleep(random.uniform(0.5, 5.0))  # before or after the start of the loop
        launch.proc.send_signal(signal.SIGINT)
        code, out = launch.result()
    finally:
        launch.close()
    assert code == 130 and out["error"] == "interrupted"
    assert not any(alive(pid) for pid in out["pids"].values())
    steps = recorded_steps(bag)
    assert steps == list(range(len(steps)))
    assert out["bag"]["received"] == out["bag"]["written"] == out["bag"]["messages"]


@pytest.mark.heavy
def test_nodes_idle_without_a_simulator(tmp_path: Path) -> None:
    """With no simulator the sensing, control and quality nodes wait without burning CPU."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(fresh_domain_id()), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    # (PYTHONFAULTHANDLER is on for the tests' processes, conftest: a node that hangs is aborted below and shows where)
    logs = [tmp_path / f"{n}.err" for n in NODES[1:]]
    procs = [subprocess.Popen([sys.executable, "-m", f"contgrasp_ros.nodes.{n}"], env=env, stdout=subprocess.DEVNULL,
                              stderr=log.open("w")) for n, log in zip(NODES[1:], logs, strict=True)]
    try:
        # start-up (imports, numba's cached kernels, discovery): until a second in which no node
        # used more than 0.1 s of CPU, at most 30 s (on a loaded machine 4 s were not enough; a
        # node in a busy loop never gets there and is caught below)
        end = time.monotonic() + 30.0
        while time.monotonic() < end:
            before = [cpu_seconds(p.pid) for p in procs]
            time.sleep(1.0)
            if max(cpu_seconds(p.pid) - b for p, b in zip(procs, before, strict=True)) < 0.1:
                break
        cpu0 = [cpu_seconds(p.pid) for p in procs]
        time.sleep(3.0)
        used = [cpu_seconds(p.pid) - c for p, c in zip(procs, cpu0, strict=True)]
        assert all(p.poll() is None for p in procs)
    finally:
        # one after another, as the launcher stops them (ProcessGroup.stop: Fast DDS 2.14 can
        # deadlock a participant destroyed while another one leaves)
        codes = []
        for p, log in zip(procs, logs, strict=True):
            p.send_signal(signal.SIGINT)
            try:
                codes.append(p.wait(timeout=30))
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGABRT)  # faulthandler prints every thread's stack
                p.wait(timeout=30)
                raise AssertionError(f"{p.args[-1]} ignored SIGINT for 30 s; its stderr:\n{log.read_text()[-6000:]}") from None
    assert max(used) < 0.3, used  # seconds of CPU in 3 s of waiting: no busy loop
    assert codes == [0, 0, 0]


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.heavy
def test_killed_simulator_with_respawn_restarts_the_run(tmp_path: Path) -> None:
    """With --respawn the simulator is restarted, starts again from the initial state, is resumed
    by the launcher and the run completes; the recording holds both segments, each gap-free."""
    bag = tmp_path / "bag"
    launch = Launch("--params", str(fault_params(tmp_path, duration=1.0)), "--bag", str(bag), "--respawn", "1")
    try:
        running(launch)
        launch.signal("rod_simulator", signal.SIGKILL)
        launch.wait_for(r"'rod_simulator' exited with code -9; restarting it \(1/1\)")
        code, out = launch.result()
    finally:
        launch.close()
    assert code == 0, "".join(launch.lines[-40:])
    assert out["restarts"] == {"rod_simulator": 1} and out["simulator_state"] == "finished"
    assert [e["restart"] for e in launch.events if e["event"] == "resumed"] == [False, True]
    assert out["sim_time_s"] == pytest.approx(1.0)
    steps = recorded_steps(bag)
    restart = next((i for i in range(1, len(steps)) if steps[i] <= steps[i - 1]), None)  # the second run starts over
    assert restart is not None, (steps, "".join(launch.lines[-60:]))
    assert steps[:restart] == list(range(restart))
    # the restarted simulator waits for the sensor, the monitor and the recorder: its step 0 is recorded
    assert steps[restart:] == list(range(out["steps"] + 1))


def test_orphaned_shared_memory_files_are_removed_and_files_in_use_kept(tmp_path: Path) -> None:
    """Port and segment files whose lock is gone (a participant that exited normally leaves its
    port segment and mutex) are removed; a locked one, a mapped one and a young one stay."""
    import mmap

    from contgrasp_ros.launcher.processes import remove_orphans

    def make(name: str, size: int = 4096) -> Path:
        path = tmp_path / name
        path.write_bytes(b"\0" * size)
        return path

    orphan_port, orphan_mutex = make("fastrtps_port23456"), make("sem.fastrtps_port23456_mutex")
    orphan_segment = make("fastrtps_0123456789abcdef")
    locked, lock = make("fastrtps_port23457"), make("fastrtps_port23457_el")
    mapped = make("fastrtps_fedcba9876543210")
    other = make("something_else")
    with open(mapped, "r+b") as fd, mmap.mmap(fd.fileno(), 4096) as view:  # a live participant's segment
        # (maps lists the real path: the test's /tmp file stands in for /dev/shm)
        assert remove_orphans(tmp_path, min_age_s=3600.0) == []  # all young
        removed = remove_orphans(tmp_path, min_age_s=0.0)
        view[0] = 1
    assert sorted(removed) == sorted([orphan_port, orphan_segment])
    assert not orphan_mutex.exists()
    assert all(p.exists() for p in (locked, lock, mapped, other))


@pytest.mark.heavy
def test_a_recorder_lost_mid_run_leaves_the_run_unrecorded_and_the_launcher_says_so(tmp_path: Path) -> None:
    """The recorder killed mid-run (the launcher checks before the run that the recording can be
    written, so a recording lost later is a fault): the run itself completes and the launcher
    reports the recorder's failure (exit 1: the run is not recorded; --allow-unrecorded would
    accept that)."""
    launch = Launch("--params", str(fault_params(tmp_path)), "--bag", str(tmp_path / "bag"))
    code, out = killed_mid_run(launch, "mcap_recorder")
    assert code == 1 and out["exit_codes"]["mcap_recorder"] == -9, "".join(launch.lines[-40:])
    assert out["simulator_state"] == "finished" and out["steps"] > 0
    assert out["error"] == "the recorder exited with code -9: the run is not recorded (--allow-unrecorded accepts that)"
    assert f"contgrasp-launch: error: {out['error']}\n" in launch.lines  # (the failure in one line on stderr too)
