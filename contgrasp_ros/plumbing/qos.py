"""Quality-of-service profiles of the contgrasp graph (docs/design.md, section 4).

Streams (rod state, contact, couple, quality) are reliable with a small keep-last depth so the
lock-step loop never loses a step; the object boundary is transient-local so late joiners
(a restarted sensor, a recorder) still receive it.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

STREAM = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
