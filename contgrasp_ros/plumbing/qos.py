"""Quality-of-service profiles of the contgrasp graph (docs/design.md, section 4).

Streams (rod state, contact, couple, quality) are reliable and volatile, keep-last 100: the
lock-step loop never loses a step, and a subscriber outside the loop (a recorder) that falls
behind by up to 100 samples still gets every one (a reliable writer keeps only its history for
the readers that have not acknowledged; with 10, a recorder starved of CPU while the loop ran
on lost 15 of 1098 rod states); the object boundary is transient-local so late joiners (a
restarted sensor, a recorder) still receive it.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

STREAM = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
