"""
Property tests (hypothesis): inputs drawn from a space, each checked against a reference.

SO(3) exp/log/retract round trips and Jacobians near 0 and near pi; message validation
(accepted iff valid, never a crash); the box QP's KKT conditions on random SPD and
semi-definite problems; the Robotino mapping; the trajectory maths; message conversions.
Examples are bounded (``max_examples``, no deadline) so that the file runs in seconds.
"""

import math

from cbha_inverse.core import so3
from cbha_inverse.core.chain import ChainState, retract
from cbha_inverse.core.inverse.qp import (ActiveSetQP, projected_gauss_seidel, ProxsuiteQP,
                                          QPProblem)
from cbha_inverse.robot.robotino import CHANNELS, MAX_BAR, robotino_bar_command
from cbha_inverse.robot.safety import (
    bounded_command, check_command, check_point, CommandGate, stale_action, StalenessWatch,
    WorkspaceBox)
from cbha_inverse.robot.trajectory import (
    circle_trajectory, PLANES, polyline_points, square_trajectory, waypoint_trajectory)
from cbha_inverse.ros.common.conversions import (
    command_array, command_message, point_array, point_stamped, point_values, SerializedCommand)
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

PROPERTY = settings(max_examples=100, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])

FINITE = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
ANY_FLOAT = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                      st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -0.0]))


@st.composite
def unit_vectors(draw):
    """Draw a unit vector (3,) from a normal triple away from 0."""
    v = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(3)])
    if np.linalg.norm(v) < 1e-3:
        v = np.array([1.0, 0.0, 0.0])
    return v / np.linalg.norm(v)


# angles: exactly 0, tiny (series branches), moderate, the 2.4 rad branch switch, near pi
ANGLES = st.one_of(st.just(0.0), st.floats(1e-12, 1e-4), st.floats(1e-4, 3.0),
                   st.floats(2.3, 2.5), st.floats(math.pi - 1e-3, math.pi - 1e-9))


@st.composite
def rotation_vectors(draw, angles=ANGLES):
    """Draw a rotation vector axis * angle with the angle from ``angles`` [rad]."""
    return draw(unit_vectors()) * draw(angles)


# SO(3) ------------------------------------------------------------------------------------
@PROPERTY
@given(rotation_vectors())
def test_exp_is_a_rotation_and_log_inverts_it(rotvec):
    rot = so3.so3_exp(rotvec)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-14)
    # Rodrigues independently: R v = v (the axis is fixed), tr R = 1 + 2 cos(theta)
    theta = np.linalg.norm(rotvec)
    np.testing.assert_allclose(rot @ rotvec, rotvec, atol=1e-14)
    assert np.trace(rot) == pytest.approx(1.0 + 2.0 * math.cos(theta), abs=1e-14)
    back = so3.so3_log(rot)
    # near pi the log has a conditioning of ~1 / (pi - theta) in its direction: bound it so
    np.testing.assert_allclose(back, rotvec, atol=1e-13 / max(math.pi - theta, 1e-3))


@PROPERTY
@given(rotation_vectors())
def test_quaternion_round_trip(rotvec):
    rot = so3.so3_exp(rotvec)
    quat = so3.quat_from_matrix(rot)
    assert np.linalg.norm(quat) == pytest.approx(1.0, abs=1e-15) and quat[3] >= 0.0
    theta = np.linalg.norm(rotvec)
    # the closed form q = (sin(t/2) axis, cos(t/2)) for t in [0, pi]
    np.testing.assert_allclose(quat[:3], np.sinc(0.5 * theta / np.pi) * 0.5 * rotvec,
                               atol=1e-14)
    np.testing.assert_allclose(so3.matrix_from_quat(quat), rot, atol=1e-14)


@PROPERTY
@given(rotation_vectors(st.one_of(st.floats(0.0, 1e-5), st.floats(1e-5, 3.0),
                                  st.floats(math.pi - 0.05, math.pi - 0.01))),
       unit_vectors())
def test_left_jacobian_inverse_against_central_differences(rotvec, direction):
    """``log(exp(e) exp(phi)) = phi + Jl^-1(phi) e + O(e^2)``: central differences in ``e``."""
    step = 1e-6
    base = so3.so3_exp(rotvec)
    plus = so3.so3_log(so3.so3_exp(step * direction) @ base)
    minus = so3.so3_log(so3.so3_exp(-step * direction) @ base)
    numeric = (plus - minus) / (2.0 * step)
    np.testing.assert_allclose(so3.so3_left_jacobian_inverse(rotvec) @ direction, numeric,
                               atol=2e-6)


@PROPERTY
@given(st.integers(1, 4), st.data())
def test_retract_moves_every_frame_but_the_base_by_its_increment(n, data):
    frames = data.draw(st.lists(rotation_vectors(), min_size=n + 1, max_size=n + 1))
    offsets = data.draw(st.lists(st.tuples(FINITE, FINITE, FINITE), min_size=n + 1,
                                 max_size=n + 1))
    turns = data.draw(st.lists(rotation_vectors(), min_size=n, max_size=n))
    steps = data.draw(st.lists(st.tuples(FINITE, FINITE, FINITE), min_size=n, max_size=n))
    rotations = so3.so3_exp(np.array(frames))
    state = ChainState(np.array(offsets), rotations.copy())
    increments = np.concatenate([np.array(steps) * 1e-3, np.array(turns)], axis=1)
    moved = retract(state, increments)
    np.testing.assert_array_equal(moved.positions[0], state.positions[0])
    np.testing.assert_array_equal(moved.rotations[0], state.rotations[0])
    np.testing.assert_allclose(moved.positions[1:] - state.positions[1:], increments[:, :3],
                               atol=1e-12)
    # world-axis (left) increment: log(R_new R_old^T) = dtheta
    relative = moved.rotations[1:] @ np.swapaxes(state.rotations[1:], -1, -2)
    for got, want in zip(so3.so3_log(relative), increments[:, 3:]):
        distance_to_pi = max(math.pi - np.linalg.norm(want), 1e-3)
        np.testing.assert_allclose(got, want, atol=1e-13 / distance_to_pi)
    np.testing.assert_array_equal(state.rotations, rotations)  # the input is not modified


# message validation -----------------------------------------------------------------------
BOX = WorkspaceBox((-0.5, -0.5, -0.5), (0.8, 0.5, 0.5))
FRAMES = st.sampled_from(['cbha_base', 'cbha_base ', '', 'world', 'CBHA_BASE', 'map'])


@PROPERTY
@given(st.lists(ANY_FLOAT, min_size=0, max_size=5), FRAMES)
def test_check_point_accepts_exactly_the_valid_points(values, frame):
    check = check_point(values, frame, 'cbha_base', BOX)
    point = np.asarray(values, dtype=float)
    # a list of floats (the nodes' path), a tuple and an array: the same verdict
    for same in (tuple(values), point):
        other = check_point(same, frame, 'cbha_base', BOX)
        assert (other.ok, other.reason) == (check.ok, check.reason)
    valid = (point.shape == (3,) and bool(np.all(np.isfinite(point)))
             and frame == 'cbha_base'
             and all(lo <= v <= hi for v, lo, hi in zip(point, BOX.lower, BOX.upper)))
    assert check.ok == valid
    assert check.ok or (check.reason in ('non_finite', 'wrong_frame', 'outside_workspace')
                        and check.detail)
    if point.shape == (3,) and np.all(np.isfinite(point)) and frame != 'cbha_base':
        assert check.reason == 'wrong_frame'


@PROPERTY
@given(st.lists(st.one_of(ANY_FLOAT, st.floats(-1.0, 2e5)), min_size=0, max_size=9),
       st.integers(1, 8), st.floats(0.0, 2e5))
def test_check_command_accepts_exactly_the_valid_commands(values, n_valves, max_pressure):
    check = check_command(values, n_valves, max_pressure)
    valid = (len(values) == n_valves and all(math.isfinite(v) and 0.0 <= v <= max_pressure
                                             for v in values))
    assert check.ok == valid
    assert check.ok or check.reason in ('wrong_length', 'non_finite', 'out_of_range')
    if len(values) != n_valves:
        assert check.reason == 'wrong_length'


@PROPERTY
@given(st.lists(ANY_FLOAT, min_size=0, max_size=7), st.integers(1, 6))
def test_bounded_command_never_lets_a_bad_value_through(values, m):
    lower = np.linspace(0.0, 10.0, m)
    upper = lower + 1e5
    gate = CommandGate(lower, upper)
    # a list, and a float array (the nodes' path through the gate)
    for command in (values, np.array(values, dtype=float)):
        if len(values) == m and all(math.isfinite(v) for v in values):
            for out in (bounded_command(command, lower, upper), gate(command)):
                assert out.dtype == np.float64 and out.shape == (m,)
                np.testing.assert_array_equal(out, np.minimum(np.maximum(values, lower), upper))
        else:
            for gated in (lambda: bounded_command(command, lower, upper), lambda: gate(command)):
                with pytest.raises(ValueError):
                    gated()


@PROPERTY
@given(st.floats(1e-3, 10.0), st.floats(0.0, 20.0), st.floats(0.0, 20.0), st.booleans(),
       st.booleans(), st.sampled_from(['hold', 'vent']))
def test_staleness_decision(timeout, target_age, feedback_age, closed, never_fed, action):
    target = StalenessWatch(timeout)
    feedback = StalenessWatch(timeout)
    now = 100.0
    target.mark(now - target_age)
    if not never_fed:
        feedback.mark(now - feedback_age)
    assert target.age(now) == pytest.approx(target_age)
    assert feedback.age(now) == (math.inf if never_fed else pytest.approx(feedback_age))
    # the age is now - mark, as floats: compare the timeout with that difference
    target_stale = now - (now - target_age) > timeout
    feedback_stale = never_fed or now - (now - feedback_age) > timeout
    assert target.stale(now) == target_stale and feedback.stale(now) == feedback_stale
    # a stale target stays the set-point: only stale feedback in closed loop holds or vents
    decision = stale_action(feedback.stale(now), closed, action)
    expected = action if closed and feedback_stale else 'run'
    assert decision == expected


# the Robotino mapping ---------------------------------------------------------------------
@PROPERTY
@given(st.permutations(sorted(CHANNELS)), st.integers(0, 8), st.data(),
       st.floats(0.0, MAX_BAR))
def test_robotino_mapping_puts_each_named_pressure_on_its_channel(names, count, data, max_bar):
    names = tuple(names[:count])
    pressures = data.draw(st.lists(st.one_of(ANY_FLOAT, st.floats(-1e5, 3e5)),
                                   min_size=count, max_size=count))
    out = robotino_bar_command(pressures, names, max_bar=max_bar)
    assert out.shape == (8,) and np.all(np.isfinite(out))
    assert np.all(out >= 0.0) and np.all(out <= max_bar)
    expected = np.zeros(8)
    for name, pressure in zip(names, pressures):
        bar = pressure / 1e5 if math.isfinite(pressure) else 0.0
        expected[CHANNELS[name]] = min(max(bar, 0.0), max_bar)
    np.testing.assert_allclose(out, expected, rtol=1e-15, atol=0.0)


@PROPERTY
@given(st.lists(st.sampled_from(sorted(CHANNELS) + ['gripper', 'inner']), min_size=1,
                max_size=9), st.integers(-1, 1), st.floats(-1.0, 3.0))
def test_robotino_mapping_rejects_bad_names_lengths_and_caps(names, extra, max_bar):
    valid = (len(set(names)) == len(names) and all(n in CHANNELS for n in names)
             and extra == 0 and 0.0 <= max_bar <= MAX_BAR)
    pressures = np.full(max(len(names) + extra, 0), 1e4)
    if valid:
        assert robotino_bar_command(pressures, names, max_bar=max_bar).shape == (8,)
    else:
        with pytest.raises(ValueError):
            robotino_bar_command(pressures, names, max_bar=max_bar)


# the box QP -------------------------------------------------------------------------------
@st.composite
def box_qps(draw, rank_deficit=0):
    """Draw a box QP ``min ½ xᵀHx + gᵀx, l <= x <= u``: H = AᵀA, rank m - rank_deficit."""
    m = draw(st.integers(1 + rank_deficit, 8))
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((m - rank_deficit, m)) * np.geomspace(1.0, 1e-2, m)
    hessian = a.T @ a
    if rank_deficit == 0:
        hessian += 1e-3 * np.eye(m)
    gradient = draw(st.floats(0.1, 10.0)) * rng.standard_normal(m)
    lower = -rng.uniform(0.0, 2.0, m)
    upper = lower + rng.uniform(1e-3, 3.0, m)
    previous = rng.uniform(-2.0, 2.0, m)
    return QPProblem(hessian, gradient, lower, upper, np.ones(m), previous, hessian, gradient)


def _assert_kkt(problem, x, tolerance):
    """Box-QP optimality: x in the box, zero gradient when free, the right sign when bound."""
    h, g, lower, upper = problem.hessian, problem.gradient, problem.lower, problem.upper
    scale = 1.0 + np.abs(h).sum(axis=1) * np.maximum(np.abs(lower), np.abs(upper)) + np.abs(g)
    assert np.all(x >= lower) and np.all(x <= upper)
    grad = (h @ x + g) / scale
    at_lower = x <= lower + tolerance
    at_upper = x >= upper - tolerance
    free = ~(at_lower | at_upper)
    assert np.all(np.abs(grad[free]) <= tolerance), (grad, x, lower, upper)
    assert np.all(grad[at_lower & ~at_upper] >= -tolerance)
    assert np.all(grad[at_upper & ~at_lower] <= tolerance)


def _objective(problem, x):
    return 0.5 * x @ problem.hessian @ x + problem.gradient @ x


@PROPERTY
@given(box_qps())
def test_active_set_qp_satisfies_kkt_on_spd_problems(problem):
    solution = ActiveSetQP(problem.gradient.size).solve(problem)
    assert solution.ok and solution.status == 'solved'
    _assert_kkt(problem, solution.x, 1e-9)
    # projected Gauss-Seidel (the paper's solver) reaches the same minimum
    gauss_seidel = projected_gauss_seidel(problem, max_iterations=20000, tolerance=1e-13)
    assert _objective(problem, gauss_seidel.x) == pytest.approx(
        _objective(problem, solution.x), rel=1e-6, abs=1e-9)


@PROPERTY
@given(box_qps(rank_deficit=1))
def test_semidefinite_box_qp_solutions_satisfy_kkt(problem):
    """Rank-deficient H: proxsuite meets KKT to its tolerance; active set exact or fallback."""
    proxsuite_solution = ProxsuiteQP(problem.gradient.size, eps_abs=1e-10).solve(problem)
    assert proxsuite_solution.status == 'solved'
    _assert_kkt(problem, proxsuite_solution.x, 1e-5)
    active = ActiveSetQP(problem.gradient.size).solve(problem)
    if active.ok:
        _assert_kkt(problem, active.x, 1e-8)
        assert _objective(problem, active.x) <= _objective(problem, proxsuite_solution.x) + 1e-7
    else:
        # the documented fallback value: the previous actuation, clipped into the box
        np.testing.assert_array_equal(
            active.x, np.minimum(np.maximum(problem.previous, problem.lower), problem.upper))


# trajectories -----------------------------------------------------------------------------
CENTERS = st.tuples(*[st.floats(-1.0, 1.0)] * 3)


@PROPERTY
@given(CENTERS, st.floats(1e-3, 1.0), st.sampled_from(PLANES), st.floats(1e-3, 1.0),
       st.lists(st.floats(0.0, 1e3), min_size=2, max_size=20), st.floats(0.0, 5.0))
def test_circle_samples_lie_on_the_circle_at_the_travelled_angle(center, radius, plane, speed,
                                                                 times, hold):
    path = circle_trajectory(center, radius, plane, speed, start_hold=hold)
    points = path.sample(times)
    axis = {'x': 0, 'y': 1, 'z': 2}
    u_axis, v_axis = axis[plane[0]], axis[plane[1]]
    normal = 3 - u_axis - v_axis
    offset = points - np.asarray(center)
    np.testing.assert_allclose(np.linalg.norm(offset, axis=1), radius, rtol=1e-12)
    np.testing.assert_allclose(offset[:, normal], 0.0, atol=1e-15)
    # the angle travelled is speed * (t - hold) / r, counter-clockwise from the +u axis
    angle = speed * np.maximum(np.asarray(times) - hold, 0.0) / radius
    np.testing.assert_allclose(offset[:, u_axis], radius * np.cos(angle), atol=1e-9 * radius
                               * (1.0 + angle.max()))
    np.testing.assert_allclose(offset[:, v_axis], radius * np.sin(angle), atol=1e-9 * radius
                               * (1.0 + angle.max()))


@PROPERTY
@given(CENTERS, st.floats(1e-3, 1.0), st.sampled_from(PLANES), st.floats(1e-3, 1.0),
       st.floats(0.0, 0.999), st.integers(0, 3))
def test_square_perimeter_and_speed(center, side, plane, speed, fraction, laps):
    path = square_trajectory(center, side, plane, speed, laps=laps)
    assert path.length == pytest.approx(4.0 * side) and path.lap_time == path.length / speed
    time = fraction * path.lap_time
    point = path.sample(time)[0]
    offset = point - np.asarray(center)
    # every point of the square is on its boundary: the larger in-plane offset is side / 2
    assert np.max(np.abs(offset)) == pytest.approx(0.5 * side, rel=1e-9)
    # the distance along the path is speed * time: the sum of the pieces up to the point
    s = path.arc_length(time)[0]
    assert s == pytest.approx(speed * time, rel=1e-9, abs=1e-12)
    if laps:
        assert path.finished(path.duration) and not path.finished(0.999 * path.duration)
        np.testing.assert_allclose(path.sample(path.duration + 1.0)[0], path.vertices[-1],
                                   atol=1e-12)
    else:
        assert path.duration == math.inf and not path.finished(1e9)


@PROPERTY
@given(st.lists(st.tuples(*[st.floats(-1.0, 1.0)] * 3), min_size=2, max_size=6),
       st.lists(st.floats(-0.5, 10.0), min_size=1, max_size=10))
def test_polyline_points_are_at_their_arc_length(vertices, arc_lengths):
    vertices = np.array(vertices)
    pieces = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    cumulative = np.concatenate([[0.0], np.cumsum(pieces)])
    points = polyline_points(vertices, arc_lengths)
    for s, point in zip(np.clip(arc_lengths, 0.0, cumulative[-1]), points):
        # walk the pieces: the distance to the start along the polyline equals s
        k = min(np.searchsorted(cumulative, s, side='right') - 1, len(pieces) - 1)
        along = cumulative[k] + np.linalg.norm(point - vertices[k])
        assert along == pytest.approx(s, abs=1e-12)
        between = np.linalg.norm(point - vertices[k]) + np.linalg.norm(vertices[k + 1] - point)
        assert between == pytest.approx(pieces[k], abs=1e-12)


@PROPERTY
@given(st.lists(st.tuples(*[st.floats(-1.0, 1.0)] * 3), min_size=2, max_size=5),
       st.floats(1e-3, 1.0), st.booleans(), st.floats(0.0, 100.0))
def test_waypoint_paths_open_and_looped(waypoints, speed, loop, time):
    vertices = np.array(waypoints)
    if np.all(np.linalg.norm(np.diff(vertices, axis=0), axis=1) == 0.0):
        with pytest.raises(ValueError):
            waypoint_trajectory(vertices, speed, loop=loop)
        return
    path = waypoint_trajectory(vertices.reshape(-1), speed, loop=loop)
    expected = np.sum(np.linalg.norm(np.diff(vertices, axis=0), axis=1))
    if loop:
        expected += np.linalg.norm(vertices[-1] - vertices[0])
    assert path.length == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(path.sample(0.0)[0], vertices[0], atol=1e-15)
    if not loop:
        np.testing.assert_allclose(path.sample(path.duration + time)[0], vertices[-1],
                                   atol=1e-12)


# message conversions ----------------------------------------------------------------------
@PROPERTY
@given(st.tuples(ANY_FLOAT, ANY_FLOAT, ANY_FLOAT), st.text(max_size=12),
       st.integers(0, 2 ** 31 - 1), st.integers(0, 999_999_999))
def test_point_message_round_trip(point, frame, sec, nanosec):
    from builtin_interfaces.msg import Time
    message = point_stamped(point, Time(sec=sec, nanosec=nanosec), frame)
    assert message.header.frame_id == frame
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (sec, nanosec)
    np.testing.assert_array_equal(point_array(message), np.array(point, dtype=float))
    np.testing.assert_array_equal(point_values(message), np.array(point, dtype=float))


@PROPERTY
@given(st.lists(ANY_FLOAT, max_size=10), st.data())
def test_command_message_round_trip(values, data):
    names = data.draw(st.lists(st.text(alphabet='abcdefgh_', min_size=1, max_size=8),
                               min_size=len(values), max_size=len(values)))
    message = command_message(values, names)
    assert len(message.layout.dim) == 1
    dim = message.layout.dim[0]
    assert dim.label == ','.join(names) and dim.size == len(names) == dim.stride
    np.testing.assert_array_equal(command_array(message), np.array(values, dtype=float))
    assert command_array(message).shape == (len(values),)
    # the serialized command is rclpy's serialization of that message (the same length, the
    # doubles bit for bit at its end; the alignment padding after the label is not compared:
    # the serializer need not initialise it, and one run in many differed there), and reads
    # back as it
    if values:
        from rclpy.serialization import deserialize_message, serialize_message
        from std_msgs.msg import Float64MultiArray
        array = np.array(values, dtype=float)
        serialized = SerializedCommand(names).serialize(array)
        reference = serialize_message(message)
        assert len(serialized) == len(reference)
        assert serialized[-array.nbytes:] == reference[-array.nbytes:] == array.tobytes()
        decoded = deserialize_message(serialized, Float64MultiArray)
        assert decoded.layout == message.layout
        np.testing.assert_array_equal(np.array(decoded.data), np.array(values, dtype=float))
