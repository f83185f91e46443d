"""What a launcher run reports is true, means one thing and survives a crash, with
real node processes: every time key says its clock, the domain comes from the environment and
is announced, a lock-step recording is stamped with simulated time, a recording cut short by a
killed recorder recovers and analyses with its own scenario, a lost recording fails the run
unless allowed, and ``analyze`` exits 1 when a recording does not recompute."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

pytestmark = pytest.mark.heavy(per_module=True)  # (its tests share one recorded paper run: one shard makes it)

pytest.importorskip("rclpy")

from conftest import fresh_domain_id  # noqa: E402

from contgrasp_ros.bag.reader import info, iter_raw, open_recording  # noqa: E402
from contgrasp_ros.bag.writer import RUN_RECORD, BagWriter  # noqa: E402
from contgrasp_ros.launcher.launch_handle import LaunchHandle  # noqa: E402
from contgrasp_ros.launcher.cli import default_params_file  # noqa: E402

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[1]
CLI_DOC = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")

# the time keys of every command's JSON and their clock (docs/cli.md, "Times say their clock")
SIM_MOMENTS = {"settle_time_s", "settle_time_recomputed_s"}


def contgrasp(*argv: str, check: bool = True) -> tuple[int, dict[str, Any], str]:
    proc = subprocess.run([str(BIN / "contgrasp"), *argv, "--json"], capture_output=True, text=True, timeout=600)
    if check:
        assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.returncode, json.loads(proc.stdout) if proc.stdout.strip() else {}, proc.stderr


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The packaged paper scenario through separate node processes, recorded (the default
    simulated log time), the domain taken from the environment (no --domain-id)."""
    tmp = tmp_path_factory.mktemp("paper")
    bag = tmp / "run.mcap"
    domain = fresh_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    proc = subprocess.run([str(BIN / "contgrasp-launch"), "--bag", str(bag), "--json"], capture_output=True, text=True,
                          timeout=900, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {"bag": bag, "domain": domain, "summary": json.loads(proc.stdout), "stderr": proc.stderr}


def time_keys(obj: Any, path: str = "") -> list[tuple[str, str]]:
    """(path, key) of every key ending in ``_s`` in a JSON value (not ``_per_s``: a rate)."""
    out: list[tuple[str, str]] = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k.endswith("_s") and not k.endswith("_per_s"):
                out.append((f"{path}.{k}", k))
            out += time_keys(v, f"{path}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:3]):
            out += time_keys(v, f"{path}[{i}]")
    return out


def test_the_domain_comes_from_the_environment_and_is_announced(paper_run: dict[str, Any]) -> None:
    d = paper_run["domain"]
    first = paper_run["stderr"].splitlines()[0]
    assert first.startswith(f"[launcher] ROS_DOMAIN_ID={d} ") and f"ROS_DOMAIN_ID={d} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in first
    assert paper_run["summary"]["domain_id"] == d


def test_the_recording_is_stamped_with_simulated_time(paper_run: dict[str, Any]) -> None:
    """A lock-step run of 2.2 s of simulated time spans 2.2 s of log time (it took far longer)."""
    s = paper_run["summary"]
    assert s["settled"] and s["sim_time_s"] == pytest.approx(2.194, abs=1e-9)
    assert s["bag"]["log_time_clock"] == "sim" and s["bag"]["wall_time_s"] is None
    assert s["bag"]["sim_time_s"] == pytest.approx(s["sim_time_s"], abs=1e-6)
    meta = info(open_recording(paper_run["bag"]))
    assert meta["log_time_clock"] == "sim" and meta["sim_time_s"] == s["bag"]["sim_time_s"] and meta["wall_time_s"] is None
    assert meta["start_ns"] == 0 and meta["end_ns"] == round(2.194e9)
    # every rod state is logged at its own stamp
    rod = [m for m in iter_raw(open_recording(paper_run["bag"])) if m.topic == "/contgrasp/rod_state"]
    assert len(rod) == s["steps"] + 1 and rod[-1].log_time_ns == meta["end_ns"]


def test_the_summary_names_its_contact_set(paper_run: dict[str, Any]) -> None:
    s = paper_run["summary"]
    assert s["contact_nodes"] >= 40 and 0.08 < s["contact_length"] < 0.12
    assert s["mean_abs_rho_ratio_minus_1_contact"] <= s["max_abs_rho_ratio_minus_1_contact"]
    assert s["mean_abs_alpha_minus_half_pi_contact"] <= s["max_abs_alpha_minus_half_pi_contact"]


def test_no_time_key_means_two_things(paper_run: dict[str, Any], tmp_path: Path) -> None:
    """Every key ending in _s in the JSON of simulate, contgrasp-launch, bag info and analyze
    names its clock (sim or wall) or is a documented moment of the simulation; each is in
    docs/cli.md or docs/analysis.md; the ambiguous duration_s is gone."""
    outputs = {
        "contgrasp-launch": paper_run["summary"],
        "bag info": contgrasp("bag", "info", str(paper_run["bag"]))[1],
        "analyze": contgrasp("analyze", str(paper_run["bag"]))[1],
        "simulate": contgrasp("simulate", "--duration", "0.1", "--nodes", "21")[1],
    }
    docs = CLI_DOC + (ROOT / "docs" / "analysis.md").read_text(encoding="utf-8")
    seen = set()
    for command, out in outputs.items():
        keys = time_keys(out)
        assert keys, command
        for path, key in keys:
            assert "sim" in key or "wall" in key or key in SIM_MOMENTS, f"{command}: {path}"
            assert not ("sim" in key and "wall" in key), f"{command}: {path}"
            assert f"`{key}`" in docs, f"{command}: {key} is not documented"
            seen.add(key)
    assert "duration_s" not in seen
    assert {"sim_time_s", "wall_time_s", "settle_time_s"} <= seen


def fault_params(tmp_path: Path, duration: float) -> Path:
    """The packaged scenario on a coarse rod (fast steps; see tests/test_faults.py) that does not
    settle early, with a sensor tolerance other than the default: the analysis of a recovered
    recording must find it in the recording (the scenario written when the bag opened)."""
    data = yaml.safe_load(default_params_file().read_text())
    data["/**"]["ros__parameters"]["n_elements"] = 20
    data["rod_simulator"]["ros__parameters"].update(duration=duration, couple_timeout=0.5, marker_period=0.0, min_time=10.0,
                                                    max_penetration_limit=0.01)
    data["boundary_sensor"]["ros__parameters"]["contact_tolerance"] = 0.0012
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def killed_recorder_run(tmp_path: Path, *extra: str) -> tuple[int, dict[str, Any], Path]:
    bag = tmp_path / "killed.mcap"
    launch = LaunchHandle("--domain-id", str(fresh_domain_id()), "--params", str(fault_params(tmp_path, 3.0)),
                          "--bag", str(bag), *extra)
    try:
        launch.wait_for(r"graph connected; the simulator is running")
        time.sleep(2.0)  # several flush periods (0.5 s) of the running loop reach the disk
        launch.signal("mcap_recorder", signal.SIGKILL)
        launch.wait_for(r"the recorder exited with code -9; the run continues unrecorded")
        code, out = launch.result()
    finally:
        launch.close()
    assert out["simulator_state"] == "finished" and out["exit_codes"]["mcap_recorder"] == -9
    assert {"node": "mcap_recorder", "exit_code": -9, "action": "continued unrecorded"} in out["faults"]
    return code, out, bag


def test_a_lost_recording_fails_the_run_and_the_recovered_bag_analyses_with_its_scenario(tmp_path: Path) -> None:
    code, out, bag = killed_recorder_run(tmp_path)
    assert code == 1 and out["error"] == ("the recorder exited with code -9: the run is not recorded "
                                          "(--allow-unrecorded accepts that)")
    rc, _, err = contgrasp("bag", "info", str(bag), check=False)
    assert rc == 2 and "contgrasp bag recover" in err  # no footer: cut short
    fixed = tmp_path / "recovered.mcap"
    rec = contgrasp("bag", "recover", str(bag), str(fixed))[1]
    assert rec["chunks_kept"] > 0 and rec["messages"] > 0  # (the cut may fall between records)
    # the copy's own chunk count is the one `bag info` shows (it once reported 45 where 42 were)
    assert rec["output_chunks"] == contgrasp("bag", "info", str(fixed))[1]["chunk_count"] > 0
    meta = open_recording(fixed).metadata_records()
    assert json.loads(meta[RUN_RECORD]["params"])["boundary_sensor"]["contact_tolerance"] == 0.0012
    assert meta["contgrasp_log_time"]["clock"] == "sim"
    a = contgrasp("analyze", str(fixed))[1]
    assert a["recompute_parameters"]["source"] == "run parameters"
    assert a["recompute_parameters"]["sensor_contact_tolerance"] == 0.0012
    assert a["recomputed_pairs"]["contact"] > 0 and a["max_recompute_error"] <= 1e-9
    assert a["recompute_mismatches"] == {"in_contact": 0, "valid": 0}


def test_allow_unrecorded_accepts_a_lost_recording(tmp_path: Path) -> None:
    code, out, _ = killed_recorder_run(tmp_path, "--allow-unrecorded")
    assert code == 0 and "error" not in out


def test_analyze_exits_1_when_the_recording_does_not_recompute(paper_run: dict[str, Any], tmp_path: Path) -> None:
    """The paper recording with a wrong sensor tolerance in its run parameters: the contact
    flags and the quality recomputed from the rod states differ from the recorded ones."""
    src = open_recording(paper_run["bag"])
    records = src.metadata_records()
    run = dict(records[RUN_RECORD])
    params = json.loads(run["params"])
    params["boundary_sensor"]["contact_tolerance"] = 0.002
    run["params"] = json.dumps(params)
    dst = tmp_path / "tampered.mcap"
    w = BagWriter(dst, layout="file", open_records={RUN_RECORD: run})
    for m in iter_raw(src):
        w.add_topic(m.topic, m.type, m.channel.metadata.get("offered_qos_profiles", ""),
                    m.channel.metadata.get("topic_type_hash", ""), definition=m.schema.data.decode())
        w.write(m.topic, m.data, m.log_time_ns, m.publish_time_ns, m.sequence)
    w.close()
    code, out, err = contgrasp("analyze", str(dst), check=False)
    assert code == 1, err
    assert out["recompute_parameters"]["sensor_contact_tolerance"] == 0.002 and out["recompute_mismatches"]["in_contact"] > 0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and re.match(r"contgrasp analyze: error: the recording does not recompute: ", lines[0]), err
    assert contgrasp("analyze", str(paper_run["bag"]), check=False)[0] == 0
