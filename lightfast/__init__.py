"""lightfast: keep a camera localized while daylight changes.

The core library. It depends on NumPy, SciPy, Open3D, Embree (embreex), OpenCV and rosbags, and never imports
rclpy: everything that talks to ROS lives in :mod:`lightfast.ros` and in the node packages.
"""
from lightfast.errors import LightfastError

__version__ = "0.1.0"
__all__ = ["LightfastError", "__version__"]
