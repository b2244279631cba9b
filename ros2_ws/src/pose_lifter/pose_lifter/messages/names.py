"""Topic and message type names, written once.

The topics are those of a bag the package writes or lifts (the scene generator's inputs and
ground truth, the offline lift's outputs); the node's are the same names, relative
(``keypoints_2d``, ``camera_info``, ``skeletons_3d``, ``skeleton_markers``), so that a namespace
or a remapping moves them. The type names are the full ROS names (``package/msg/Name``).
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "BODIES_NS",
    "CAMERA_INFO",
    "COMPRESSED_IMAGE",
    "IMAGE",
    "LIFTER_NODE",
    "MARKER_ARRAY",
    "PER_BODY",
    "SKELETON2D_ARRAY",
    "SKELETON3D_ARRAY",
    "TF_TOPIC",
    "TOPIC_CAMERA_INFO",
    "TOPIC_DEPTH",
    "TOPIC_DEPTH_COMPRESSED",
    "TOPIC_GROUND_TRUTH",
    "TOPIC_KEYPOINTS",
    "TOPIC_MARKERS",
    "TOPIC_SKELETONS",
    "YOLO_DETECTION_ARRAY",
]

#: The lifter node's name (the adapter recognises the lifter's own REP-155 output by it).
LIFTER_NODE: Final[str] = "pose_lifter"
#: The 2D input (``Skeleton2DArray``).
TOPIC_KEYPOINTS: Final[str] = "/keypoints_2d"
#: The camera intrinsics (``CameraInfo``).
TOPIC_CAMERA_INFO: Final[str] = "/camera_info"
#: The depth image registered to the keypoints' camera (``Image``, 16UC1 millimetres or 32FC1 metres):
#: RealSense's aligned depth topic.
TOPIC_DEPTH: Final[str] = "/camera/aligned_depth_to_color/image_raw"
#: The same image as image_transport's ``compressedDepth`` records it (``CompressedImage``).
TOPIC_DEPTH_COMPRESSED: Final[str] = TOPIC_DEPTH + "/compressedDepth"
#: The lifted skeletons (``Skeleton3DArray``, camera optical frame, metres).
TOPIC_SKELETONS: Final[str] = "/skeletons_3d"
#: Joints and bones per track (``MarkerArray``).
TOPIC_MARKERS: Final[str] = "/skeleton_markers"
#: The generated scenes' true 3D skeletons (``Skeleton3DArray``).
TOPIC_GROUND_TRUTH: Final[str] = "/ground_truth/skeletons_3d"

SKELETON2D_ARRAY: Final[str] = "pose_lifter_msgs/msg/Skeleton2DArray"
SKELETON3D_ARRAY: Final[str] = "pose_lifter_msgs/msg/Skeleton3DArray"
MARKER_ARRAY: Final[str] = "visualization_msgs/msg/MarkerArray"
CAMERA_INFO: Final[str] = "sensor_msgs/msg/CameraInfo"
IMAGE: Final[str] = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE: Final[str] = "sensor_msgs/msg/CompressedImage"
#: yolo_ros' detections (with keypoints), lifted through :mod:`pose_lifter.messages.adapters`.
YOLO_DETECTION_ARRAY: Final[str] = "yolo_msgs/msg/DetectionArray"

# REP-155 (ros4hri) bodies (:mod:`pose_lifter.messages.hri`), absolute names as REP-155 fixes them.
#: Each body's topics (``BODIES_NS/<id>/<kind>``) and their types; ``urdf`` is latched.
PER_BODY: Final[dict[str, str]] = {"urdf": "std_msgs/msg/String", "skeleton2d": "hri_msgs/msg/Skeleton2D",
                                   "roi": "hri_msgs/msg/NormalizedRegionOfInterest2D",
                                   "joint_states": "sensor_msgs/msg/JointState"}
#: The namespace of bodies.
BODIES_NS: Final[str] = "/humans/bodies"
#: The topic of the bodies' frames (``tf2_msgs/TFMessage``).
TF_TOPIC: Final[str] = "/tf"
