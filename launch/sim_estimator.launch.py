"""The simulator on sim time, the estimator on /clock, and (optionally) the recorder.

    ros2 launch rozyn_estimator sim_estimator.launch.py [road:=laplace] [class:=B]
        [amplitudes:=fixed] [speed_kmh:=50 | drive_cycle:=udds] [duration_s:=300] [vehicle_file:=my_car.yaml]
        [load_change_kg:=150 load_change_x_m:=0.6 load_change_at_s:=340]
        [model:=full] [record:=true] [bag_dir:=bags] [real_time_factor:=5]

The simulator (``config/sim.yaml``, on sim time at ``real_time_factor`` times real time,
starting once its accelerometer topics are subscribed) drives a half car over the chosen
road (``model:=full``: the full car of ``config/vehicle_full.yaml``, or of any vehicle file
that says ``model: full``, with four corner accelerometers); the estimator
(``config/estimator.yaml``) uses the same vehicle file and the sim's speed; with
``record:=true`` the sim starts once the recorder has subscribed too, so the bag holds the
estimator's first samples and ``rozyn replay`` of it updates at the same stamps (measured:
every estimate, within 1e-5). Unlike ``rozyn
demo`` (one process, paced by what the estimator takes in), these are separate processes
without flow control: the default 5x leaves the estimator time for every update on two
cores (at 20x here it skipped updates and lost 14 % of the samples to a saturated CPU).
With ``duration_s`` > 0 everything stops when the sim is done; otherwise Ctrl-C stops
it (every node exits with status 0; the recorder closes its bag).
"""

from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.launch_description import LaunchDescription
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

PACKAGE = "rozyn_estimator"


def generate_launch_description() -> LaunchDescription:
    config = PathJoinSubstitution([FindPackageShare(PACKAGE), "config"])
    arg = LaunchConfiguration
    by_model = PythonExpression(["'vehicle_full.yaml' if '", arg("model"), "' == 'full' else 'vehicle.yaml'"])
    arguments = [
        DeclareLaunchArgument("road", default_value="iso", choices=["iso", "laplace", "flat"],
                              description="road model: ISO 8608, Laplace (Bogsjo) or flat"),
        DeclareLaunchArgument("class", default_value="A", choices=list("ABCDEFGH"),
                              description="ISO 8608 road class"),
        DeclareLaunchArgument("amplitudes", default_value="gaussian", choices=["fixed", "gaussian"],
                              description="gaussian (a true random road) or fixed (the thesis' generator)"),
        DeclareLaunchArgument("speed_kmh", default_value="100.0", description="vehicle speed [km/h]"),
        DeclareLaunchArgument("drive_cycle", default_value="",
                              description="follow a drive cycle instead of speed_kmh: udds, hwfet, wltc3b "
                                          "or a CSV of time_s and speed_kmh"),
        DeclareLaunchArgument("load_change_kg", default_value="0.0",
                              description="a point load put in at a stop of the drive cycle [kg] (0: none)"),
        DeclareLaunchArgument("load_change_x_m", default_value="0.0",
                              description="where that load sits behind the centre of gravity [m]"),
        DeclareLaunchArgument("load_change_at_s", default_value="0.0",
                              description="when the load changes [s]: the vehicle must stand then"),
        DeclareLaunchArgument("duration_s", default_value="0.0",
                              description="simulated time [s] (the launch ends with it); 0: until Ctrl-C"),
        DeclareLaunchArgument("real_time_factor", default_value="5.0",
                              description="sim seconds per wall second (0: as fast as possible); faster "
                              "than the estimator's updates and it skips some, faster than 3 processes "
                              "on the cores can carry and samples are lost"),
        DeclareLaunchArgument("model", default_value="half", choices=["half", "full"],
                              description="half car (front and rear accelerometers) or full car (four "
                              "corners); a vehicle_file saying model: full is a full car anyway"),
        DeclareLaunchArgument("vehicle_file", default_value=PathJoinSubstitution([config, by_model]),
                              description="vehicle YAML, for the sim (the truth) and the estimator (default: "
                              "config/vehicle.yaml, with model:=full config/vehicle_full.yaml)"),
        DeclareLaunchArgument("record", default_value="false", choices=["true", "false"],
                              description="record everything with bag_recorder"),
        DeclareLaunchArgument("bag_dir", default_value="bags",
                              description="where the recorder writes sim-<UTC time>/"),
    ]
    vehicle = ParameterValue(arg("vehicle_file"), value_type=str)
    model = ParameterValue(arg("model"), value_type=str)
    sim = Node(
        package=PACKAGE, executable="sim_node", name="sim_node", output="screen",
        parameters=[
            PathJoinSubstitution([config, "sim.yaml"]),
            {
                "road.kind": ParameterValue(arg("road"), value_type=str),
                "road.class": ParameterValue(arg("class"), value_type=str),
                "road.amplitudes": ParameterValue(arg("amplitudes"), value_type=str),
                "speed_kmh": ParameterValue(arg("speed_kmh"), value_type=float),
                "drive_cycle_file": ParameterValue(arg("drive_cycle"), value_type=str),
                **{name: ParameterValue(arg(name), value_type=float)
                   for name in ("load_change_kg", "load_change_x_m", "load_change_at_s")},
                "duration_s": ParameterValue(arg("duration_s"), value_type=float),
                "real_time_factor": ParameterValue(arg("real_time_factor"), value_type=float),
                "vehicle_file": vehicle,
                "vehicle.model": model,
                # recording: the sim starts once the recorder subscribed too (the bag then holds
                # the estimator's first samples, which anchor rozyn replay's update schedule)
                "subscribers_per_topic": ParameterValue(
                    PythonExpression(["2 if '", arg("record"), "' == 'true' else 1"]), value_type=int),
            },
        ],
    )
    estimator = Node(
        package=PACKAGE, executable="estimator_node", name="estimator_node", output="screen",
        parameters=[
            PathJoinSubstitution([config, "estimator.yaml"]),
            {"use_sim_time": True, "speed_topic": "sim/speed", "vehicle_file": vehicle,
             "vehicle.model": model, "qos_depth": 10000},
        ],
    )
    recorder = Node(
        package=PACKAGE, executable="bag_recorder", name="bag_recorder", output="screen",
        condition=IfCondition(arg("record")),
        parameters=[{
            "use_sim_time": True,
            "bag_root": ParameterValue(arg("bag_dir"), value_type=str),
            "name": "sim",
            "qos_depth": 10000,
        }],
    )
    done = RegisterEventHandler(OnProcessExit(target_action=sim, on_exit=[EmitEvent(event=Shutdown(
        reason="the simulation is done"))]))
    return LaunchDescription([*arguments, recorder, estimator, sim, done])
