"""The estimator alone, for a vehicle: its parameter files and topics as arguments.

    ros2 launch rozyn_estimator estimator.launch.py vehicle_file:=my_car.yaml \\
        [params_file:=my_estimator.yaml] [front_topic:=/imu/front] [rear_topic:=/imu/rear] \\
        [inertia_topic:=/vehicle/inertia] [speed_topic:=/odom] [speed_topic_type:=odometry] \\
        [use_sim_time:=true] [namespace:=car1]
    ros2 launch rozyn_estimator estimator.launch.py vehicle_file:=my_full_car.yaml \\
        [front_left_topic:=/imu/fl] [front_right_topic:=/imu/fr] [rear_left_topic:=/imu/rl] \\
        [rear_right_topic:=""]   # a full car (model: full), here with three sensors

``params_file`` (default: the package's ``config/estimator.yaml``) holds the estimator's
settings and ``vehicle_file`` the vehicle's (default: ``config/vehicle.yaml``, the
thesis' Table 5-1; a full car's file, ``model: full``, makes the node the full car's, on
the four corner topics, of which one may be empty). The accelerometer topics override the
parameter file's (``front_topic``/``rear_topic`` … parameters, not remaps, so a
``bag_recorder`` stores the topics the node really reads and ``rozyn replay`` finds them);
``inertia_topic`` remaps the outputs ``inertia`` and ``inertia/covariance`` together.
"""

from launch.actions import DeclareLaunchArgument
from launch.launch_description import LaunchDescription
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

PACKAGE = "rozyn_estimator"
CORNERS = ("front_left", "front_right", "rear_left", "rear_right")  # the full car's accelerometers


def generate_launch_description() -> LaunchDescription:
    config = PathJoinSubstitution([FindPackageShare(PACKAGE), "config"])
    arg = LaunchConfiguration
    arguments = [
        DeclareLaunchArgument("vehicle_file", default_value=PathJoinSubstitution([config, "vehicle.yaml"]),
                              description="vehicle YAML (flat or ROS parameters)"),
        DeclareLaunchArgument("params_file", default_value=PathJoinSubstitution([config, "estimator.yaml"]),
                              description="estimator_node's parameter file"),
        DeclareLaunchArgument("front_topic", default_value="accel/front",
                              description="front accelerometer (sensor_msgs/Imu)"),
        DeclareLaunchArgument("rear_topic", default_value="accel/rear",
                              description="rear accelerometer (sensor_msgs/Imu)"),
        *(DeclareLaunchArgument(f"{corner}_topic", default_value=f"accel/{corner}",
                                description=f"full car: {corner.replace('_', ' ')} accelerometer "
                                "(sensor_msgs/Imu); empty: none there")
          for corner in CORNERS),
        DeclareLaunchArgument("inertia_topic", default_value="inertia",
                              description="the estimates (and <inertia_topic>/covariance)"),
        DeclareLaunchArgument("speed_topic", default_value="",
                              description="vehicle speed topic; empty: speed_mps of the parameter file"),
        DeclareLaunchArgument("speed_topic_type", default_value="twist", choices=["twist", "odometry"],
                              description="type of speed_topic: TwistStamped or Odometry"),
        DeclareLaunchArgument("use_sim_time", default_value="false", choices=["true", "false"],
                              description="run on /clock (bag playback, simulation)"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the node"),
    ]
    estimator = Node(
        package=PACKAGE, executable="estimator_node", name="estimator_node", output="screen",
        namespace=arg("namespace"),
        parameters=[
            arg("params_file"),
            {
                "vehicle_file": ParameterValue(arg("vehicle_file"), value_type=str),
                "front_topic": ParameterValue(arg("front_topic"), value_type=str),
                "rear_topic": ParameterValue(arg("rear_topic"), value_type=str),
                **{f"{c}_topic": ParameterValue(arg(f"{c}_topic"), value_type=str) for c in CORNERS},
                "speed_topic": ParameterValue(arg("speed_topic"), value_type=str),
                "speed_topic_type": ParameterValue(arg("speed_topic_type"), value_type=str),
                "use_sim_time": ParameterValue(arg("use_sim_time"), value_type=bool),
            },
        ],
        remappings=[
            ("inertia", arg("inertia_topic")),
            ("inertia/covariance", [arg("inertia_topic"), "/covariance"]),
        ],
    )
    return LaunchDescription([*arguments, estimator])
