"""
Simulation: trajectory + inverse_solver + cbha_sim (+ stereo_tracker with feedback:=stereo, or
shape_estimator with feedback:=proprio).

``ros2 launch cbha_inverse sim.launch.py [name:=value ...]``; ``ros2 launch cbha_inverse
sim.launch.py --show-args`` lists the arguments. The composition is the table
``cbha_inverse.ros.launch.compositions.COMPOSITIONS['sim']``, which ``cbha_launch sim`` runs
without the ``launch`` package: both start the same nodes with the same params files and
overrides (docs/nodes.md).
"""

from cbha_inverse.ros.launch.compositions import COMPOSITIONS, resolve
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

COMPOSITION = COMPOSITIONS['sim']


def _nodes(context):
    values = {argument.name: LaunchConfiguration(argument.name).perform(context)
              for argument in COMPOSITION.all_arguments()}
    return [Node(package='cbha_inverse', executable=process.executable,
                 name=process.executable, namespace=process.namespace,
                 parameters=[*process.params_files, process.parameters],
                 additional_env=process.environment or None, output='screen')
            for process in resolve(COMPOSITION, values)]


def generate_launch_description():
    """Declare the composition's arguments and start its nodes."""
    arguments = [DeclareLaunchArgument(argument.name, **argument.declaration())
                 for argument in COMPOSITION.all_arguments()]
    return LaunchDescription([*arguments, OpaqueFunction(function=_nodes)])
