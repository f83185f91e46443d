"""A monitor of the run in a process of its own (so a test can starve it with SIGSTOP): it keeps
the last rod state's step and the simulator's last status; it prints ``ready`` once it has heard
both (its readers matched), and when the run has finished and the final state is in, or on
SIGINT, prints them as one JSON line and exits.

Usage: python probe_process.py  (ROS_DOMAIN_ID from the environment)."""

from __future__ import annotations

import json
import signal

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor

from contgrasp_msgs.msg import RodState
from contgrasp_ros.plumbing import qos, topics


def main() -> None:
    stopped = []
    signal.signal(signal.SIGINT, lambda *_: stopped.append(True))
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node("starved_probe")
    seen: dict[str, object] = {"state": None, "status_step": None, "last_step": None}

    def on_status(msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == "rod_simulator":
                values = {kv.key: kv.value for kv in st.values}
                seen["state"], seen["status_step"] = values.get("state"), int(values.get("step", -1))

    def on_state(msg: RodState) -> None:
        seen["last_step"] = msg.step

    node.create_subscription(RodState, topics.ROD_STATE, on_state, qos.STREAM)
    node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_status, qos.STREAM)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    ready = False
    while not stopped and not (seen["state"] == "finished" and seen["last_step"] == seen["status_step"]):
        executor.spin_once(timeout_sec=0.05)
        if not ready and seen["state"] is not None and seen["last_step"] is not None:
            print("ready", flush=True)
            ready = True
    print(json.dumps(seen), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
