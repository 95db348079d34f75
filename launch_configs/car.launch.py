"""The car's perception: driver_adapter + detection + mapping for one camera.

    ros2 launch cone_perception car.launch.py                       # example_mainhoop camera
    ros2 launch cone_perception car.launch.py camera:=mainhoop      # launch_configs/mainhoop.params.yaml
    ros2 launch cone_perception car.launch.py fused:=true           # one `pipeline` process instead
    ros2 launch cone_perception car.launch.py track:=true           # + the cone tracker (/cones/tracked)
    ros2 launch cone_perception car.launch.py tf:=true rviz:=true   # + camera transform, rviz2
    ros2 launch cone_perception car.launch.py respawn:=false        # a node that dies stays dead

``camera`` names ``launch_configs/<camera>.params.yaml`` (parameters of all nodes, including the
calibration file). ``image_topic`` is remapped to the nodes' ``image_raw`` input.
``respawn`` (default true): a perception node that exits (a crash, ``kill -9``) is started again
after ``respawn_delay`` seconds (default 1.0); its start removes the shared-memory files its
predecessor left (``cone_perception.nodes._shm``), so it gets frames again at once (docs/robustness.md).
``tf:=true`` starts tf2_ros ``static_transform_publisher`` for ``rear_axle`` ->
``<calibration camera>_optical_frame`` (or ``camera_frame:=...``) from the calibration's mount pose
(``cone_perception.geometry.transforms``). ``rviz:=true`` starts rviz2 with ``launch_configs/cone_perception.rviz``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _true(context, name):
    return LaunchConfiguration(name).perform(context).lower() in ("1", "true", "yes")


def _nodes(context):
    share = get_package_share_directory("cone_perception")
    camera = LaunchConfiguration("camera").perform(context)
    params = os.path.join(share, "launch_configs", f"{camera}.params.yaml")
    if not os.path.isfile(params):
        raise RuntimeError(f"no parameter file {params} for camera {camera!r}")
    image_topic = LaunchConfiguration("image_topic").perform(context)
    fused = _true(context, "fused")
    track = _true(context, "track")
    remap = [("image_raw", image_topic), ("image_raw/compressed", image_topic + "/compressed")]
    try:
        delay = float(LaunchConfiguration("respawn_delay").perform(context))
    except ValueError:
        raise RuntimeError("respawn_delay must be a number of seconds") from None
    # the perception nodes come back after a crash (rviz2 and the transform publisher do not need to)
    again = {"respawn": _true(context, "respawn"), "respawn_delay": max(0.0, delay)}
    extra = []
    if _true(context, "tf"):
        from cone_perception.geometry.calib import DEFAULT_CAMERA, load_calibration
        from cone_perception.geometry.transforms import calibration_in_params_file, optical_frame_transform

        calib = load_calibration(calibration_in_params_file(params) or DEFAULT_CAMERA)
        tf = optical_frame_transform(calib, LaunchConfiguration("camera_frame").perform(context) or None)
        extra.append(Node(package="tf2_ros", executable="static_transform_publisher", name="camera_transform",
                          arguments=tf.args(), output="screen"))
    if _true(context, "rviz"):
        extra.append(Node(package="rviz2", executable="rviz2", name="rviz2", output="screen",
                          arguments=["-d", os.path.join(share, "launch_configs", "cone_perception.rviz")]))
    if fused:
        return [Node(package="cone_perception", executable="pipeline", name="pipeline",
                     parameters=[params, {"track": track}], remappings=remap, output="screen", **again)] + extra
    tracker = [Node(package="cone_perception", executable="cone_tracker", name="cone_tracker",
                    parameters=[params], output="screen", **again)] if track else []
    return extra + tracker + [
        Node(package="cone_perception", executable="driver_adapter", name="driver_adapter",
             parameters=[params], remappings=remap, output="screen", **again),
        Node(package="cone_perception", executable="detection", name="detection",
             parameters=[params], output="screen", **again),
        Node(package="cone_perception", executable="mapping", name="mapping",
             parameters=[params], output="screen", **again),
    ]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("camera", default_value="example_mainhoop",
                              description="launch_configs/<camera>.params.yaml to use"),
        DeclareLaunchArgument("image_topic", default_value="/camera/image_raw",
                              description="camera driver's image topic"),
        DeclareLaunchArgument("fused", default_value="false",
                              description="run the fused pipeline node instead of three nodes"),
        DeclareLaunchArgument("track", default_value="false",
                              description="also track the cones (/cones/tracked): the pipeline's tracker stage or a cone_tracker node"),
        DeclareLaunchArgument("tf", default_value="false",
                              description="publish the static transform rear_axle -> camera optical frame "
                                          "(from the calibration's mount pose)"),
        DeclareLaunchArgument("camera_frame", default_value="",
                              description="the camera's optical frame (default <calibration camera>_optical_frame)"),
        DeclareLaunchArgument("respawn", default_value="true",
                              description="start a perception node again when it exits (a crash, kill -9)"),
        DeclareLaunchArgument("respawn_delay", default_value="1.0",
                              description="seconds before a node that exited is started again"),
        DeclareLaunchArgument("rviz", default_value="false",
                              description="start rviz2 with launch_configs/cone_perception.rviz"),
        OpaqueFunction(function=_nodes),
    ])
