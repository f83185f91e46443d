"""contgrasp_ros: rclpy nodes wrapping :mod:`contgrasp_core` (docs/design.md, section 3).

The nodes, launcher and recorder are built by the ROS-graph and recording issues; this
package intentionally holds no numerics of its own.
"""
