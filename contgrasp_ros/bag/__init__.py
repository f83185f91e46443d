"""Recordings: MCAP bags written the way rosbag2's MCAP storage writes them (docs/design.md, section 5).

* :mod:`.definitions` - full message-definition text from the installed ``.msg`` files
* :mod:`.rosbag2` - rosbag2's conventions: QoS YAML, ``metadata.yaml``, the ``rosbag2`` record
* :mod:`.writer` - :class:`~.writer.BagWriter` (chunked, compressed, flushed so a killed
  recorder loses at most the open chunk)
* :mod:`.reader` - opening, validating, decoding (no ROS needed), ``bag info``, recovery

Nothing in this package imports rclpy: recordings can be read and analysed without ROS.
"""

from .errors import BagError, BagInputError, BagIOError

__all__ = ["BagError", "BagInputError", "BagIOError"]
