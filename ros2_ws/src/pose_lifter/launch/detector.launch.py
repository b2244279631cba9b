"""Launch a detector adapter in front of the pose_lifter node.

    ros2 launch pose_lifter detector.launch.py input_type:=yolo detections_topic:=/yolo/detections
    ros2 launch pose_lifter detector.launch.py input_type:=hri image_width:=640 image_height:=480

``input_type:=yolo`` reads yolo_ros' ``yolo_msgs/DetectionArray``; ``input_type:=hri`` reads every
REP-155 ``/humans/bodies/<id>/skeleton2d`` (``hri_msgs/Skeleton2D``, normalised: give the image
size, or remap ``camera_info``). The adapter publishes ``keypoints_2d`` (wang12), the lifter
``skeletons_3d`` and ``skeleton_markers``. Needs launch and launch_ros (a normal ROS 2 Jazzy install).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    arguments = [
        DeclareLaunchArgument("input_type", default_value="yolo", description="yolo or hri"),
        DeclareLaunchArgument("detections_topic", default_value="/yolo/detections",
                              description="yolo: the yolo_msgs/DetectionArray topic"),
        DeclareLaunchArgument("layout", default_value="coco17", description="yolo: keypoint layout"),
        DeclareLaunchArgument("image_width", default_value="0", description="hri: pixels (0 = camera_info)"),
        DeclareLaunchArgument("image_height", default_value="0", description="hri: pixels (0 = camera_info)"),
        DeclareLaunchArgument("camera_info_topic", default_value="camera_info"),
        DeclareLaunchArgument("frame_id", default_value="camera",
                              description="frame of inputs whose header has an empty frame_id"),
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare("pose_lifter"), "config", "lifter.yaml"]),
            description="YAML with the pose_lifter node's parameters"),
    ]
    adapter = Node(
        package="pose_lifter", executable="adapter", name="pose_lifter_adapter", output="screen",
        parameters=[{
            "input_type": LaunchConfiguration("input_type"),
            "layout": LaunchConfiguration("layout"),
            "image_width": LaunchConfiguration("image_width"),
            "image_height": LaunchConfiguration("image_height"),
            "frame_id": LaunchConfiguration("frame_id"),
        }],
        remappings=[("yolo/detections", LaunchConfiguration("detections_topic")),
                    ("camera_info", LaunchConfiguration("camera_info_topic"))],
    )
    lifter = Node(
        package="pose_lifter", executable="lifter", name="pose_lifter", output="screen",
        parameters=[LaunchConfiguration("params_file")],
        remappings=[("camera_info", LaunchConfiguration("camera_info_topic"))],
    )
    return LaunchDescription([*arguments, adapter, lifter])
