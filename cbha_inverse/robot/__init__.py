"""
What faces the real arm, no ROS: input checks and fail-safe decisions, targets, Robotino I/O.

:mod:`~cbha_inverse.robot.safety` (checks of points and commands, command bounds, hold / vent
decisions), :mod:`~cbha_inverse.robot.targets` (the closed loop's target history),
:mod:`~cbha_inverse.robot.trajectory` (reference paths) and :mod:`~cbha_inverse.robot.robotino`
(our command to the Robotino driver's channels and back).
"""
