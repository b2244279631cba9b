"""Launch the pose_lifter node with a params YAML and topic remappings.

    ros2 launch pose_lifter lifter.launch.py
    ros2 launch pose_lifter lifter.launch.py params_file:=/path/to/my.yaml \\
        keypoints_topic:=/detector/keypoints camera_info_topic:=/camera/camera_info

Needs launch and launch_ros (a normal ROS 2 Jazzy install; they are not on the package index).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    arguments = [
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare("pose_lifter"), "config", "lifter.yaml"]),
            description="YAML with the pose_lifter node's parameters",
        ),
        DeclareLaunchArgument("keypoints_topic", default_value="keypoints_2d",
                              description="input pose_lifter_msgs/Skeleton2DArray"),
        DeclareLaunchArgument("camera_info_topic", default_value="camera_info",
                              description="optional input sensor_msgs/CameraInfo"),
        DeclareLaunchArgument("skeletons_topic", default_value="skeletons_3d",
                              description="output pose_lifter_msgs/Skeleton3DArray"),
        DeclareLaunchArgument("markers_topic", default_value="skeleton_markers",
                              description="output visualization_msgs/MarkerArray"),
        DeclareLaunchArgument("log_level", default_value="info"),
    ]
    lifter = Node(
        package="pose_lifter",
        executable="lifter",
        name="pose_lifter",
        output="screen",
        emulate_tty=True,
        parameters=[LaunchConfiguration("params_file")],
        remappings=[
            ("keypoints_2d", LaunchConfiguration("keypoints_topic")),
            ("camera_info", LaunchConfiguration("camera_info_topic")),
            ("skeletons_3d", LaunchConfiguration("skeletons_topic")),
            ("skeleton_markers", LaunchConfiguration("markers_topic")),
        ],
        arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
    )
    return LaunchDescription([*arguments, lifter])
