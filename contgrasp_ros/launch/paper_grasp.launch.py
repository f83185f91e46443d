"""The paper's closed-loop grasp (Sec. V-C): simulator, boundary sensor, controller, quality node.

    ros2 launch contgrasp_ros paper_grasp.launch.py [object:=ellipse] [outline:=mine.csv]
        [law:=paper|hold|reactive] [object_mode:=fixed|spring|free] [max_muscle_stress:=PA] [friction:=MU] [params_file:=FILE] [lockstep:=true|false] [duration:=S] [compose:=true]
        [record:=true] [bag:=bags/mine] [on_finish:=idle|exit] [rviz:=true]

``--show-args`` lists them. The graph is contgrasp-launch's (contgrasp_ros.launcher.graph); include this
file from your own launch file to reuse it (docs/ros.md, "In a ROS 2 workspace").
"""

from launch import LaunchDescription

from contgrasp_ros.launcher.graph import LOOP
from contgrasp_ros.launcher.ros_launch import graph_description


def generate_launch_description() -> LaunchDescription:
    return graph_description(LOOP, lockstep=True)
