"""
``inverse_solver`` commanded besides ``target``: effector topics, a trajectory action, teleop.

The thin rclpy shell of ``docs/commanding.md`` around :mod:`cbha_inverse.robot.goals`, owned by
:class:`cbha_inverse.ros.nodes.inverse_solver.InverseSolverNode` (``self.commanding``), whose
callbacks run one at a time in its executor (:func:`cbha_inverse.ros.common.runner.
spin_until_stopped`): no lock is needed between the action, the topics and the solver's timer.

- ``targets/<effector>`` (PointStamped, one topic per scene effector): that effector's target;
  ``target`` is the first effector's. An effector without a target yet holds its model position.
- ``target_poses/<effector>`` (PoseStamped; ``target_pose``: the first effector's): its position
  and, for an ``axis`` or ``pose`` effector (``docs/effectors.md``), the orientation it
  constrains.
- ``~/follow_trajectory`` (control_msgs/action/FollowJointTrajectory, its
  ``multi_dof_trajectory``): the goal is checked (:func:`cbha_inverse.robot.goals.make_goal`,
  against each effector's reachable set), then at every solver tick its path sets the targets
  (:func:`cbha_inverse.robot.goals.plan_goal`) and, for the ``axis`` and ``pose`` effectors it
  orients, the solver's orientation targets, and the tolerances are checked
  (:class:`cbha_inverse.robot.goals.GoalMonitor`) against the actual effectors: the measured tip
  in closed loop, the model's otherwise (the orientations are always the model's). A new goal
  preempts the running one (aborted); a cancel or a path tolerance violation holds the
  effectors where they are (the targets, positions and orientations, set there; the arm never
  vents). While a goal runs, ``target``, ``targets/*``, the pose topics and the teleop topics
  are refused (counted, logged).
- ``~/delta_twist_cmds`` (geometry_msgs/TwistStamped: the first effector's linear velocity) and
  ``~/pose_target_cmds`` (geometry_msgs/PoseStamped: its position approached at
  ``teleop_max_speed``): the target moves at every solver tick, inside the workspace box and
  the reachable set, until no command came for ``teleop_timeout`` (then it holds).
"""

import math
import time

from cbha_inverse.core.so3 import quat_from_matrix, so3_exp
from cbha_inverse.robot import goals
from cbha_inverse.ros.common.conversions import stamp_ns
from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.scene.reach import sample_reachable_set
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointComponentTolerance
from geometry_msgs.msg import (PointStamped, PoseStamped, Quaternion, Transform, TwistStamped,
                               Vector3)
import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from trajectory_msgs.msg import MultiDOFJointTrajectoryPoint

MAX_TELEOP_STEP_S = 0.1
"""Longest time [s] one tick integrates a teleop velocity over (a late tick moves no farther)."""


def _seconds(duration):
    return duration.sec + 1e-9 * duration.nanosec


def _transforms(points, rotations):
    """Return a MultiDOFJointTrajectoryPoint of (k, 3) positions [m] and (k, 3, 3) rotations."""
    message = MultiDOFJointTrajectoryPoint()
    for (x, y, z), (qx, qy, qz, qw) in zip(np.asarray(points, dtype=float),
                                           quat_from_matrix(rotations).reshape(-1, 4)):
        message.transforms.append(Transform(translation=Vector3(x=x, y=y, z=z),
                                            rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
    return message


def _angle_tolerances(entries):
    """Return ``name -> angle [rad]`` of the ROTATION entries of JointComponentTolerance."""
    angles = {}
    for entry in entries:
        if entry.component != JointComponentTolerance.ROTATION:
            raise goals.GoalError(goals.INVALID_GOAL, (
                f'a component tolerance of {entry.joint_name} on component {entry.component}: '
                f'only ROTATION ({JointComponentTolerance.ROTATION}) is read (an angle); a '
                'distance is JointTolerance.position'))
        angles[entry.joint_name] = entry.position
    return angles


class _Run:
    """A goal that runs: its handle, the checked goal, its plan once started, its result."""

    def __init__(self, handle, goal):
        self.handle = handle
        self.goal = goal
        self.plan = None
        self.monitor = None
        self.started = None
        self.finished = Future()
        self.ticks = 0


class Commanding:
    """
    The effector topics, the trajectory action and the teleop topics of one controller node.

    Parameters
    ----------
    node : cbha_inverse.ros.nodes.inverse_solver.InverseSolverNode
        The controller (its scene, solver, parameters, ``_set_target`` and ``_accepted_point``).

    """

    def __init__(self, node):
        self.node = node
        p = node.params
        names = node.scene.effector_names
        self.reach = None
        if p.reach_samples:
            started = time.perf_counter()
            try:
                self.reach = [sample_reachable_set(node.scene, p.reach_samples, effector=name)
                              for name in names]
            except (RuntimeError, ValueError) as exc:
                node.get_logger().warn(f'no reachable set ({exc}): goals and teleop targets '
                                       'are not checked against the reach')
            else:
                node.get_logger().info(f'reachable sets of {list(names)}: {p.reach_samples} '
                                       f'samples in {time.perf_counter() - started:.2f} s')
        self.run = None
        self.teleop = None          # (kind, vector or point, steady time of the command)
        self.teleop_tick = None     # node time of the last teleop tick
        self.teleop_moving = False
        for index, name in enumerate(names):
            node.create_subscription(
                PointStamped, f'targets/{name}',
                lambda message, i=index, n=name: node._on_target(message, i, f'targets/{n}'),
                TARGET_QOS)
            node.create_subscription(
                PoseStamped, f'target_poses/{name}',
                lambda message, i=index, n=name: self._on_target_pose(message, i,
                                                                      f'target_poses/{n}'),
                TARGET_QOS)
        node.create_subscription(
            PoseStamped, 'target_pose',
            lambda message: self._on_target_pose(message, 0, 'target_pose'), TARGET_QOS)
        node.create_subscription(TwistStamped, '~/delta_twist_cmds', self._on_twist, TARGET_QOS)
        node.create_subscription(PoseStamped, '~/pose_target_cmds', self._on_pose, TARGET_QOS)
        self.server = ActionServer(node, FollowJointTrajectory, '~/follow_trajectory',
                                   self._execute, goal_callback=lambda goal: GoalResponse.ACCEPT,
                                   cancel_callback=lambda handle: CancelResponse.ACCEPT)

    def refused(self, topic):
        """Count and log a streaming message refused because a goal runs; return whether."""
        if self.run is None:
            return False
        self.node._count_rejected(topic, 'goal_active', 'a ~/follow_trajectory goal runs '
                                  '(cancel it first)')
        return True

    def destroy(self):
        """Destroy the action server."""
        self.server.destroy()

    # the action -------------------------------------------------------------------------------
    async def _execute(self, handle):
        """Check a goal, preempt the running one, and wait for the ticks to end it."""
        node, p = self.node, self.node.params
        request = handle.request
        trajectory = request.multi_dof_trajectory
        try:
            if request.trajectory.joint_names or request.trajectory.points:
                raise goals.GoalError(goals.INVALID_JOINTS, 'the arm has no joints: give the '
                                      'effector positions in multi_dof_trajectory')
            positions, quaternions = self._waypoints(trajectory)
            goal = goals.make_goal(
                node.solver.effectors, trajectory.joint_names,
                [_seconds(point.time_from_start) for point in trajectory.points], positions,
                quaternions=quaternions,
                frame_transform=self._frame_transform(trajectory.header.frame_id),
                path_tolerance={t.name: t.position for t in request.path_tolerance},
                goal_tolerance={t.name: t.position for t in request.goal_tolerance},
                path_angle_tolerance=_angle_tolerances(request.component_path_tolerance),
                goal_angle_tolerance=_angle_tolerances(request.component_goal_tolerance),
                goal_time_tolerance=_seconds(request.goal_time_tolerance),
                defaults=(p.default_path_tolerance, p.default_goal_tolerance,
                          p.default_goal_time_tolerance),
                angle_defaults=(p.default_path_angle_tolerance, p.default_goal_angle_tolerance),
                reach=self.reach, reach_margin=p.reach_margin)
        except goals.GoalError as exc:
            node.get_logger().warn(f'follow_trajectory goal refused: {goals.CODE_NAMES[exc.code]}'
                                   f': {exc}')
            handle.abort()
            return self._result(exc.code, str(exc))
        if self.run is not None:
            self._end(self.run, goals.GoalOutcome(goals.SUCCESSFUL, 'preempted by a new goal',
                                                  np.zeros(0)), 'abort')
        self.teleop = None
        run = _Run(handle, goal)
        self.run = run
        node.get_logger().info(f'follow_trajectory: {len(goal.times)} waypoints of '
                               f'{list(goal.effectors)} over {goal.times[-1]:.2f} s')
        return await run.finished

    @staticmethod
    def _waypoints(trajectory):
        """Return the (n, k, 3) translations [m] and (n, k, 4) rotations of a trajectory."""
        k = len(trajectory.joint_names)
        rows, turns = [], []
        for i, point in enumerate(trajectory.points):
            if len(point.transforms) != k:
                raise goals.GoalError(goals.INVALID_GOAL, f'waypoint {i}: {len(point.transforms)}'
                                      f' transforms for {k} effectors')
            rows.append([(t.translation.x, t.translation.y, t.translation.z)
                         for t in point.transforms])
            turns.append([(t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w)
                          for t in point.transforms])
        return (np.array(rows, dtype=float).reshape(len(rows), k, 3),
                np.array(turns, dtype=float).reshape(len(turns), k, 4))

    def _frame_transform(self, frame):
        """Return ``(R, t)`` of a goal's frame in the node's (``/tf_static``), None for it."""
        node = self.node
        if not frame or frame == node.params.frame_id:
            return None
        if node.static_tf is None:
            raise goals.GoalError(goals.INVALID_GOAL, f'waypoints in frame {frame!r}, not '
                                  f'{node.params.frame_id!r}, and no /tf_static (tf2_msgs)')
        try:
            return node.static_tf.transform(frame, node.params.frame_id)
        except (LookupError, ValueError) as exc:
            raise goals.GoalError(goals.INVALID_GOAL, f'{exc} (publish its transform on '
                                  '/tf_static, e.g. cbha_static_transform)') from None

    @staticmethod
    def _result(code, text):
        result = FollowJointTrajectory.Result()
        result.error_code, result.error_string = int(code), text
        return result

    def _end(self, run, outcome, how):
        """End a run: ``how`` succeed, abort or cancel; complete its result."""
        getattr(run.handle, {'succeed': 'succeed', 'abort': 'abort',
                             'cancel': 'canceled'}[how])()
        text = f'{goals.CODE_NAMES[outcome.code]}: {outcome.text}'
        if how == 'succeed':
            self.node.get_logger().info(f'follow_trajectory {text}')
        else:
            self.node.get_logger().warn(f'follow_trajectory {how}: {text}')
        run.finished.set_result(self._result(outcome.code, outcome.text))
        self.node.target_streamed = False   # the end of a goal is a set-point, no stream lost
        if self.run is run:
            self.run = None

    def _actual(self):
        """Return the effectors now (k, 3) [m]: measured tip in closed loop, else the model."""
        node = self.node
        if node.params.mode == 'closed':
            return None if node.measured is None else np.reshape(node.measured, (1, 3))
        return node.solver.effector_positions()

    def _targets_with(self, indices, points):
        """Return the node's targets (k, 3) with the rows ``indices`` set to ``points``."""
        node = self.node
        targets = (node.solver.effector_positions().copy() if node.target is None
                   else np.reshape(node.target, (-1, 3)).copy())
        targets[indices] = points
        return targets

    def _set(self, targets):
        """Make (k, 3) targets the node's set-point ((3,) for a single effector)."""
        self.node._set_target(targets if len(targets) > 1 else targets[0])

    def _model_rotations(self):
        """Return the model's effector frame rotations (k, 3, 3) (scene order)."""
        solver = self.node.solver
        return solver.effectors.rotations(solver.state.rotations)

    def _orient(self, goal, rotations):
        """Set the orientation targets of the effectors a goal orients to (k, 3, 3) rotations."""
        if not np.any(goal.oriented):
            return
        solver = self.node.solver
        effectors = solver.effectors
        directions, quaternions = solver.orientation_targets
        for j, index in enumerate(goal.indices):
            if not goal.oriented[j]:
                continue
            if goal.kinds[j] == 'axis':
                directions[effectors.axis_effectors.index(index)] = rotations[j] @ goal.axes[j]
            else:
                quaternions[effectors.pose_effectors.index(index)] = quat_from_matrix(
                    rotations[j])
        solver.set_orientation_targets(directions=directions if len(directions) else None,
                                       quaternions=quaternions if len(quaternions) else None)

    def _hold(self, run, actual):
        """Set the targets of a goal's effectors to where they are (positions and orientations)."""
        self._set(self._targets_with(run.goal.indices, actual[run.goal.indices]))
        self._orient(run.goal, self._model_rotations()[run.goal.indices])

    def before_tick(self):
        """Move the targets of a running goal or of teleop (the solver's timer, first)."""
        if self.run is not None:
            self._goal_tick(self.run)
        elif self.teleop is not None:
            self._teleop_tick()

    def _goal_tick(self, run):
        node = self.node
        actual = self._actual()
        if run.handle.is_cancel_requested:
            if actual is not None:
                self._hold(run, actual)
            self._end(run, goals.GoalOutcome(goals.SUCCESSFUL, 'canceled: holding where the '
                                             'effectors are', np.zeros(0)), 'cancel')
            return
        if not node.enabled:
            self._end(run, goals.GoalOutcome(goals.SUCCESSFUL, f'controller stopped '
                                             f'({node.stopped}: ~/hold, ~/vent or ~/enable '
                                             'false)', np.zeros(0)), 'abort')
            return
        if actual is None:
            return      # closed loop, no measurement yet: the node waits and says so
        now = node._node_seconds()
        rotations = self._model_rotations()[run.goal.indices]
        if run.plan is None:
            run.plan = goals.plan_goal(run.goal, actual[run.goal.indices],
                                       node.params.approach_speed, rotations)
            run.monitor = goals.GoalMonitor(run.goal, run.plan)
            run.started = now
            if run.plan.delay > 0.0:
                node.get_logger().info(f'follow_trajectory: the approach at '
                                       f'{node.params.approach_speed:g} m/s delays the '
                                       f'waypoints by {run.plan.delay:.2f} s')
        elapsed = now - run.started
        outcome = run.monitor.check(elapsed, actual[run.goal.indices], rotations)
        if outcome is not None and outcome.code == goals.PATH_TOLERANCE_VIOLATED:
            self._hold(run, actual)
            self._end(run, outcome, 'abort')
            return
        desired = run.plan.desired(elapsed)
        desired_rotations = run.plan.desired_rotations(elapsed)
        self._orient(run.goal, desired_rotations)
        self._set(self._targets_with(run.goal.indices, desired))
        run.ticks += 1
        if outcome is not None:
            self._end(run, outcome, 'succeed' if outcome.succeeded else 'abort')
        elif run.ticks % node.params.feedback_every_n_ticks == 0:
            self._feedback(run, desired, actual[run.goal.indices], desired_rotations, rotations)

    def _feedback(self, run, desired, actual, desired_rotations, rotations):
        """
        Publish desired, actual and error per effector, and the saturated actuators.

        The rotations: ``actual`` the model's frame, ``error`` the rotation from it to the
        desired orientation (:func:`cbha_inverse.robot.goals.orientation_errors`: an ``axis``
        effector's shortest turn of its axis; identity where the goal orients nothing),
        ``desired`` that error applied to the actual frame.
        """
        node = self.node
        feedback = FollowJointTrajectory.Feedback()
        feedback.header.stamp = node.get_clock().now().to_msg()
        feedback.header.frame_id = node.params.frame_id
        feedback.multi_dof_joint_names = list(run.goal.effectors)
        errors = so3_exp(goals.orientation_errors(run.goal, desired_rotations, rotations))
        feedback.multi_dof_desired = _transforms(desired, errors @ rotations)
        feedback.multi_dof_actual = _transforms(actual, rotations)
        feedback.multi_dof_error = _transforms(desired - actual, errors)
        result = node.last_result
        if result is not None:
            saturated = np.flatnonzero(result.saturated)
            feedback.joint_names = [node.scene.actuator_names[i] for i in saturated]
            feedback.actual.positions = [float(result.actuation[i]) for i in saturated]
        run.handle.publish_feedback(feedback)

    # teleop -----------------------------------------------------------------------------------
    def _on_twist(self, message):
        if self.refused('delta_twist_cmds'):
            return
        velocity = self._vector(message)
        if velocity is None:
            return
        speed = float(np.linalg.norm(velocity))
        limit = self.node.params.teleop_max_speed
        if speed > limit:
            velocity = velocity * (limit / speed)
        self._command('twist', velocity)

    def _vector(self, message):
        """Return a TwistStamped's linear velocity in the node's frame, or None (rejected)."""
        node = self.node
        linear = message.twist.linear
        values = (linear.x, linear.y, linear.z)
        if not all(math.isfinite(v) for v in values):
            node._count_rejected('delta_twist_cmds', 'non_finite', f'velocity {values}')
            return None
        frame = message.header.frame_id
        if frame and frame != node.params.frame_id:
            # a velocity turns with the frame: the image of v less that of the origin
            ends = []
            for point in (values, (0.0, 0.0, 0.0)):
                stamped = PointStamped()
                stamped.header.frame_id = frame
                stamped.point.x, stamped.point.y, stamped.point.z = point
                ends.append(node._accepted_point('delta_twist_cmds', stamped, check_box=False))
                if ends[-1] is None:
                    return None
            return ends[0] - ends[1]
        return np.array(values, dtype=float)

    def _on_target_pose(self, message, effector, topic):
        """
        Take a pose target of one effector: its position, and the orientation it constrains.

        A ``pose`` effector's frame turns to the message's orientation, an ``axis`` effector's
        axis to where that orientation carries it (the effector's ``axis`` rotated by it); a
        ``point`` effector takes the position only. A pose in another frame than the node's
        ``frame_id`` is transformed by ``/tf_static``, or refused as a point is.
        """
        node = self.node
        received, received_cpu = time.perf_counter(), time.thread_time()
        if self.refused(topic):
            return
        point = node._accepted_pose_position(topic, message)
        if point is None:
            return
        effectors = node.solver.effectors
        kind = effectors.kinds[effector]
        if kind != 'point':
            try:
                rotation = node._pose_rotation(topic, message)
                directions, quaternions = node.solver.orientation_targets
                if kind == 'axis':
                    directions[effectors.axis_effectors.index(effector)] = (
                        rotation @ effectors.axes[effector])
                    node.solver.set_orientation_targets(directions=directions)
                else:
                    quaternions[effectors.pose_effectors.index(effector)] = quat_from_matrix(
                        rotation)
                    node.solver.set_orientation_targets(quaternions=quaternions)
            except ValueError as exc:
                node._count_rejected(topic, 'bad_orientation', str(exc))
                return
        node._take_target(point, effector, stamp_ns(message.header.stamp), received,
                          received_cpu)

    def _on_pose(self, message):
        if self.refused('pose_target_cmds'):
            return
        point = self.node._accepted_pose_position('pose_target_cmds', message)
        if point is not None:
            self._command('pose', point)

    def _command(self, kind, vector):
        if self.teleop is None:
            self.teleop_tick = None
        self.teleop = (kind, vector, time.monotonic())
        if not self.teleop_moving:
            self.teleop_moving = True
            self.node.get_logger().info(f'teleop: following {kind} commands')

    def _teleop_tick(self):
        node, p = self.node, self.node.params
        kind, vector, received = self.teleop
        now = node._node_seconds()
        step = 0.0 if self.teleop_tick is None else min(now - self.teleop_tick,
                                                        MAX_TELEOP_STEP_S)
        self.teleop_tick = now
        if time.monotonic() - received > p.teleop_timeout:
            if self.teleop_moving:
                self.teleop_moving = False
                node.target_streamed = False    # held on purpose: no stream lost
                node.get_logger().info(f'teleop: no command for {p.teleop_timeout:g} s, '
                                       'holding the target')
            return
        targets = self._targets_with([], np.zeros((0, 3)))
        current = targets[0]
        if kind == 'twist':
            proposed = current + vector * step
        else:
            gap = vector - current
            distance = float(np.linalg.norm(gap))
            reach = p.teleop_max_speed * step
            proposed = vector if distance <= reach else current + gap * (reach / distance)
        proposed = np.clip(proposed, node.box.lower, node.box.upper)
        if self.reach is not None:
            outside = self.reach[0].outside_distance(np.array([proposed, current]))
            if outside[0] > p.reach_margin and outside[0] > outside[1]:
                return      # no farther out of the reach: the target stays
        targets[0] = proposed
        self._set(targets)
