"""nav2 AMCL on a bag written by ``locbench export --format rosbag2 --dataset office`` (docs/external.md).

Not run in CI (no ROS there). Usage, with the export in ``office-0/``::

    ros2 launch amcl_office.launch.py data:=$PWD/office-0
    ros2 bag play office-0/bag --clock

The map server serves ``office-0/map.yaml``; AMCL reads ``office-0/nav2_amcl_params.yaml`` (the copy beside this
file, ``amcl_office_params.yaml``, is what the export writes for office seed 0) and publishes ``/amcl_pose`` and
``/particle_cloud`` in ``map``, which ``locbench import`` reads.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    data = LaunchConfiguration("data")
    params = PathJoinSubstitution([data, "nav2_amcl_params.yaml"])
    return LaunchDescription(
        [
            DeclareLaunchArgument("data", description="the folder locbench export wrote"),
            Node(
                package="nav2_map_server",
                executable="map_server",
                name="map_server",
                parameters=[{"yaml_filename": PathJoinSubstitution([data, "map.yaml"]), "use_sim_time": True}],
            ),
            Node(package="nav2_amcl", executable="amcl", name="amcl", parameters=[params]),
            Node(
                package="nav2_lifecycle_manager",
                executable="lifecycle_manager",
                name="lifecycle_manager_localization",
                parameters=[{"use_sim_time": True, "autostart": True, "node_names": ["map_server", "amcl"]}],
            ),
        ]
    )
