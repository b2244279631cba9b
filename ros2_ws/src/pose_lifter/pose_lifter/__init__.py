"""pose_lifter: robust 3D human pose lifting (Wang et al., CVPR 2014) for ROS 2 and offline use."""

__version__ = "0.1.0"
