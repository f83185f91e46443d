"""The plant alone, on the wall clock: simulator, boundary sensor, quality node (and the recorder
with record:=true), for your own controller on /contgrasp/contact -> /contgrasp/couple.

    ros2 launch contgrasp_ros plant.launch.py [object:=...] [record:=true] [rviz:=true] ...

The simulator waits for its peers, a couple publisher among them, before step 0 (up to its
peer_timeout) and sends step 0 again until the loop closes; the arguments are those of
paper_grasp.launch.py (lockstep:=false by default here).
"""

from launch import LaunchDescription

from contgrasp_ros.launcher.graph import PLANT
from contgrasp_ros.launcher.ros_launch import graph_description


def generate_launch_description() -> LaunchDescription:
    return graph_description(PLANT, lockstep=False)
