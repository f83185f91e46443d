"""contgrasp_core: the numerical library of contgrasp (numpy/scipy, no ROS).

Implements "Kinematics of continuum planar grasping": object boundaries, arm kinematics and
the contact kinematics in (rho, alpha) (Sec. II); later modules add optimal grasps, grasp
quality, feedback control and rod dynamics.
"""

__version__ = "0.1.0"
