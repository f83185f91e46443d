"""The project's figures (paper Figs. 2-4 and the contact-kinematics check), drawn with matplotlib's
object API: importing or using them never selects or switches a matplotlib backend.

* :mod:`.draw` - shared helpers (object, arm, kinematics check, saving, path checks);
* :mod:`.grasp` - Fig. 2, optimal grasps;
* :mod:`.quality_map` - Fig. 3, quality maps;
* :mod:`.closed_loop` - Fig. 4, the closed-loop grasp, and its animation;
* :mod:`.run` - a ROS graph run drawn from its topics (Fig. 4 style, quality over time).
"""
