"""The contgrasp_msgs interface package is built into the venv and round-trips through CDR."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

MSG_DIR = Path(__file__).resolve().parents[1] / "msgs_schema" / "msg"


def test_definitions_installed_for_the_recorder() -> None:
    share = Path(sys.prefix) / "share" / "contgrasp_msgs" / "msg"
    for src in MSG_DIR.glob("*.msg"):
        assert (share / src.name).read_text() == src.read_text()
    assert (Path(sys.prefix) / "share" / "ament_index" / "resource_index" / "packages" / "contgrasp_msgs").exists()


def test_cdr_round_trip() -> None:
    os.environ.setdefault("ROS_LOG_DIR", "/tmp")
    from rclpy.serialization import deserialize_message, serialize_message

    from contgrasp_msgs.msg import ContactState, GraspQuality, RodState

    rod = RodState(step=7, s=[0.0, 0.1], x=[0.0, 0.1], y=[0.0, 0.0], theta=[0.0, 0.0])
    rod.header.stamp.sec = 3
    back = deserialize_message(serialize_message(rod), RodState)
    assert back.step == 7 and back.header.stamp.sec == 3
    np.testing.assert_array_equal(back.x, [0.0, 0.1])
    q = GraspQuality(w=np.arange(9.0), q1=0.5, valid=True)
    back_q = deserialize_message(serialize_message(q), GraspQuality)
    np.testing.assert_array_equal(back_q.w, np.arange(9.0))
    c = ContactState(in_contact=[True, False])
    assert list(deserialize_message(serialize_message(c), ContactState).in_contact) == [True, False]
