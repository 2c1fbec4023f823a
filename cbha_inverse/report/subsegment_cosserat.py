"""
The reference model of Rao et al. 2021: a Cosserat rod between every two disks (an oracle).

Rao, Peyron, Lilge and Burgner-Kahrs, *How to Model Tendon-Driven Continuum Robots and Benchmark
Modelling Performance*, Frontiers in Robotics and AI 7:630245, 2021, benchmark their models of a
tendon-driven continuum robot (TDCR) against the variable-curvature model with a partially
constrained tendon path: the backbone between two neighbouring spacer disks is a Cosserat rod
free of distributed loads (Rucker and Webster, IEEE T-RO 27(6), 2011); each tendon runs in
straight spans between its holes in the disks and loads every disk it touches. This module
solves that model as the paper states it, for a comparison with the package's frame chain
(:mod:`cbha_inverse.report.benchmark_rao2021`); nothing of the package's model is used.

Conventions are the paper's: the backbone leaves the base along +z, a disk frame has its z
axis along the backbone, a tendon hole sits at ``r = [x, y, 0]`` in its disk's frame; SI units.

Between disks k and k+1 (arc length s from 0 to l_k) the rod obeys, with v and u the linear
and angular rates in the body frame and no distributed load::

    p' = R v,   R' = R û,
    v' = -Kse⁻¹ (û Kse (v - e3)),
    u' = -Kbt⁻¹ (û Kbt u + v̂ Kse (v - e3)),

``Kse = diag(GA, GA, EA)``, ``Kbt = diag(EI, EI, 2GI)``; the internal force and moment are
``n = R Kse (v - e3)`` and ``m = R Kbt u``. At disk k the rod's internal wrench jumps by the
tendon loads on that disk, ``n(s_k⁻) - n(s_k⁺) = F_k``, ``m(s_k⁻) - m(s_k⁺) = M_k`` (at the
tip, ``n(L) = F_N + F_tip`` and ``m(L) = M_N + M_tip``). A tendon of tension τ pulls its hole
on disk k toward its holes on disks k-1 and k+1 (only toward k-1 where it ends):
``τ (p_{k-1} - p_k) / |p_{k-1} - p_k| + τ (p_{k+1} - p_k) / |p_{k+1} - p_k|``. The authors'
implementation of the reference drops the component of this force along the disk's normal
where the tendon passes through a disk (a frictionless hole transmits no force along the
tendon's channel, ``pass_through = 'disk_plane'``, the default); ``'eyelet'`` keeps it, the
force of a frictionless point contact.

The boundary-value problem is solved by multiple shooting, as the authors' public code does
(github.com/SvenLilge/tdcr-modeling, ``VCref_solver.m``): the unknowns are the internal wrench
``Kse (v - e3), Kbt u`` at the start of every subsegment (6 per disk), the residuals the jumps
at every disk; each subsegment is integrated by the classical Runge-Kutta method with a fixed
step (``steps`` per subsegment), and Newton's method runs on a finite-difference Jacobian (all
perturbations integrated together as one batch) with a backtracking line search.
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, solve

_E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class TendonRobot:
    """
    A tendon-driven robot of the paper's reference model: a rod through disks, and tendons.

    Parameters
    ----------
    spacing : (N,) array_like  [m]
        Backbone length from disk k to disk k+1, k = 0..N-1 (disk 0 is the base, disk N the
        tip).
    youngs_modulus : float  [Pa]
    poisson_ratio : float
    outer_radius : float  [m]
        Of the backbone's circular section.
    inner_radius : float  [m]
        0 for a solid backbone.
    holes : (T, 3) array_like  [m]
        The hole of each tendon in a disk's frame, ``[x, y, 0]``: the same in every disk the
        tendon runs through (straight routing, parallel to the backbone at rest).
    end_disks : (T,) array_like of int
        The disk where each tendon ends (it starts at the base, disk 0).

    """

    spacing: tuple
    youngs_modulus: float
    poisson_ratio: float
    outer_radius: float
    inner_radius: float
    holes: tuple
    end_disks: tuple

    def __post_init__(self):
        """Check the shapes and ranges."""
        spacing = np.asarray(self.spacing, dtype=float)
        holes = np.asarray(self.holes, dtype=float)
        ends = np.asarray(self.end_disks)
        if spacing.ndim != 1 or spacing.size < 1 or np.any(spacing <= 0.0):
            raise ValueError('spacing must be N > 0 positive lengths')
        if holes.ndim != 2 or holes.shape[1] != 3 or ends.shape != (holes.shape[0],):
            raise ValueError('holes must be (T, 3) and end_disks (T,)')
        if np.any(ends < 1) or np.any(ends > spacing.size):
            raise ValueError(f'end_disks must lie in 1..{spacing.size}')
        if not 0.0 <= self.inner_radius < self.outer_radius:
            raise ValueError('need 0 <= inner_radius < outer_radius')

    @property
    def n_disks(self):
        """Return the number of disks N above the base."""
        return len(self.spacing)

    def stiffness(self):
        """
        Return the diagonals of ``Kse`` [N] and ``Kbt`` [N m²] (paper eq. of the rod).

        Returns
        -------
        kse : (3,) ndarray  [N]
            ``(GA, GA, EA)``, shear and extension.
        kbt : (3,) ndarray  [N m²]
            ``(EI, EI, 2GI)``, bending and torsion.

        """
        e_mod = float(self.youngs_modulus)
        g_mod = e_mod / (2.0 * (1.0 + float(self.poisson_ratio)))
        area = np.pi * (self.outer_radius ** 2 - self.inner_radius ** 2)
        inertia = np.pi * (self.outer_radius ** 4 - self.inner_radius ** 4) / 4.0
        return (np.array([g_mod * area, g_mod * area, e_mod * area]),
                np.array([e_mod * inertia, e_mod * inertia, 2.0 * g_mod * inertia]))


@dataclass(frozen=True)
class RodSolution:
    """
    The reference model's equilibrium.

    Attributes
    ----------
    positions : (N+1, 3) ndarray  [m]
        Disk centres, base first (paper frame: +z along the backbone at rest).
    rotations : (N+1, 3, 3) ndarray
        Disk frames (columns: the disk's axes in the base frame).
    residual : float  [N, N m]
        Norm of the disk equilibria at the solution.
    iterations : int
        Newton iterations, over all load steps.

    """

    positions: np.ndarray
    rotations: np.ndarray
    residual: float
    iterations: int

    @property
    def tip(self):
        """(3,) ndarray: the tip disk's centre [m]."""
        return self.positions[-1]


def _cross(a, b):
    """Return the cross products of the columns of two (3, B) arrays."""
    out = np.empty_like(a)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


def _rates(y, kse, kbt):
    """
    Return ``dy/ds`` of the rod's states, batch along the last axis.

    ``y`` (18, B): ``p`` (rows 0-2), ``R`` row-major (3-11), ``v`` (12-14), ``u`` (15-17).
    """
    v, u = y[12:15], y[15:18]
    n_local = (v - _E3[:, None]) * kse[:, None]
    m_local = u * kbt[:, None]
    dy = np.empty_like(y)
    rot = y[3:12].reshape(3, 3, -1)
    dy[0:3] = np.einsum('ijb,jb->ib', rot, v)
    d_rot = dy[3:12].reshape(3, 3, -1)
    d_rot[:, 0] = rot[:, 1] * u[2] - rot[:, 2] * u[1]      # R û, column by column
    d_rot[:, 1] = rot[:, 2] * u[0] - rot[:, 0] * u[2]
    d_rot[:, 2] = rot[:, 0] * u[1] - rot[:, 1] * u[0]
    dy[12:15] = -_cross(u, n_local) / kse[:, None]
    dy[15:18] = -(_cross(u, m_local) + _cross(v, n_local)) / kbt[:, None]
    return dy


def _integrate(y, length, steps, kse, kbt):
    """Integrate the rod over ``length`` by ``steps`` classical Runge-Kutta steps."""
    h = length / steps
    for _ in range(steps):
        k1 = _rates(y, kse, kbt)
        k2 = _rates(y + 0.5 * h * k1, kse, kbt)
        k3 = _rates(y + 0.5 * h * k2, kse, kbt)
        k4 = _rates(y + h * k3, kse, kbt)
        y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return y


def _residuals(robot, unknowns, tensions, tip_wrench, pass_through, steps, first=None):
    """
    Return the disk equilibria of a batch of unknowns, with the disk frames.

    Parameters
    ----------
    robot : TendonRobot
        The robot.
    unknowns : (6N, B) ndarray  [N, N m]
        ``Kse (v - e3), Kbt u`` at the start of each subsegment, stacked.
    first : (B,) ndarray of int, optional
        The first subsegment whose unknowns differ from those of column 0 (column 0: 0): up to
        there a column's rod is column 0's, and is not integrated again.
    tensions, tip_wrench, pass_through, steps
        As in :func:`solve_rod` (arrays).

    Returns
    -------
    residuals : (6N, B) ndarray  [N, N m]
    positions : (N+1, 3, B) ndarray  [m]
    rotations : (N+1, 3, 3, B) ndarray

    """
    kse, kbt = robot.stiffness()
    n_disks, batch = robot.n_disks, unknowns.shape[1]
    wrench = unknowns.reshape(n_disks, 6, batch)
    positions = np.zeros((n_disks + 1, 3, batch))
    rotations = np.zeros((n_disks + 1, 3, 3, batch))
    rotations[0] = np.eye(3)[:, :, None]
    res = np.zeros((n_disks, 6, batch))
    y = np.zeros((18, batch))
    y[3:12] = np.eye(3).reshape(9, 1)
    first = np.zeros(batch, dtype=int) if first is None else first
    for k in range(n_disks):
        y[12:15] = _E3[:, None] + wrench[k, :3] / kse[:, None]
        y[15:18] = wrench[k, 3:] / kbt[:, None]
        own = first <= k
        y[:, own] = _integrate(y[:, own], robot.spacing[k], steps, kse, kbt)
        y[:, ~own] = y[:, :1]
        rot = y[3:12].reshape(3, 3, batch)
        positions[k + 1], rotations[k + 1] = y[0:3], rot
        jump = np.concatenate([(y[12:15] - _E3[:, None]) * kse[:, None],
                               y[15:18] * kbt[:, None]])
        if k + 1 < n_disks:
            jump = jump - wrench[k + 1]
        res[k, :3] = np.einsum('ijb,jb->ib', rot, jump[:3])
        res[k, 3:] = np.einsum('ijb,jb->ib', rot, jump[3:])
    loads = _tendon_loads(robot, positions, rotations, tensions, pass_through)
    res -= loads
    res[-1] -= np.asarray(tip_wrench, dtype=float)[:, None]
    return res.reshape(6 * n_disks, batch), positions, rotations


def _tendon_loads(robot, positions, rotations, tensions, pass_through):
    """
    Return the wrench (force, moment about the disk centre) of the tendons on disks 1..N.

    Returns
    -------
    (N, 6, B) ndarray  [N, N m]

    """
    holes = np.asarray(robot.holes, dtype=float)
    ends = np.asarray(robot.end_disks)
    n_disks = robot.n_disks
    disks = np.arange(n_disks + 1)
    # hole positions (N+1, T, 3, B) and the tension of each span k -> k+1, (N, T)
    arms = np.einsum('kijb,tj->ktib', rotations, holes)
    points = positions[:, None] + arms
    span_tension = np.where(disks[:-1, None] < ends[None, :], tensions[None, :], 0.0)
    spans = points[1:] - points[:-1]
    units = spans / np.linalg.norm(spans, axis=2, keepdims=True)
    pull = span_tension[:, :, None, None] * units           # force of span k on disk k
    backward = -pull                                         # on disk k+1, toward disk k
    forward = np.concatenate([pull[1:], np.zeros_like(pull[:1])])
    normals = rotations[1:, :, 2]                            # (N, 3, B): the disk normals
    if pass_through == 'disk_plane':
        through = (disks[1:, None] < ends[None, :])[:, :, None, None]
        for force in (backward, forward):
            axial = np.einsum('ktib,kib->ktb', force, normals)[:, :, None]
            force -= np.where(through, axial * normals[:, None], 0.0)
    elif pass_through != 'eyelet':
        raise ValueError(f"pass_through must be 'disk_plane' or 'eyelet', got {pass_through!r}")
    force = backward + forward
    moment = np.cross(arms[1:], force, axis=2)
    return np.concatenate([force.sum(axis=1), moment.sum(axis=1)], axis=1)


def solve_rod(robot, tensions, tip_wrench=None, *, pass_through='disk_plane', steps=4,
              tolerance=1e-8, max_iterations=30, max_load_steps=32):
    """
    Solve the reference model's equilibrium under tendon tensions and a tip wrench.

    Newton's method from the straight rod on the full load; where it fails (no descent, or a
    rod that curls beyond what the shooting can integrate), on a fraction of the load first,
    the fraction halved until Newton converges and doubled after each success.

    Parameters
    ----------
    robot : TendonRobot
        The robot.
    tensions : (T,) array_like  [N]
        Tendon tensions, in the order of ``robot.holes``.
    tip_wrench : (6,) array_like, optional  [N, N m]
        Dead force and moment at the tip disk's centre, base axes (paper frame).
    pass_through : {'disk_plane', 'eyelet'}
        The force of a tendon on a disk it passes through: the paper's (its component along the
        disk normal dropped) or that of a frictionless point contact.
    steps : int
        Runge-Kutta steps per subsegment (4 moves the tip of the paper's robot by well under
        a micrometre from 16).
    tolerance : float
        Convergence: every Newton update below ``tolerance`` times its finite-difference step
        scale (1 N for forces, 0.01 N m for moments): the internal wrench known to about
        1e-8 N.
    max_iterations : int
        Newton iterations allowed per load step.
    max_load_steps : int
        Load steps allowed (attempts, successful or not).

    Returns
    -------
    RodSolution

    Raises
    ------
    ValueError
        If the tensions or the wrench have the wrong shape or are not finite, or
        ``pass_through`` is unknown.
    RuntimeError
        If the full load is not reached.

    """
    tensions = np.asarray(tensions, dtype=float).reshape(-1)
    wrench = np.zeros(6) if tip_wrench is None else np.asarray(tip_wrench, dtype=float)
    if tensions.shape != (len(robot.end_disks),) or not np.all(np.isfinite(tensions)):
        raise ValueError(f'tensions must be {len(robot.end_disks)} finite values')
    if wrench.shape != (6,) or not np.all(np.isfinite(wrench)):
        raise ValueError('tip_wrench must be 6 finite values')
    if pass_through not in ('disk_plane', 'eyelet'):
        raise ValueError(f"pass_through must be 'disk_plane' or 'eyelet', got {pass_through!r}")
    size = 6 * robot.n_disks
    scale = np.tile([1.0, 1.0, 1.0, 0.01, 0.01, 0.01], robot.n_disks)
    delta = 1e-7 * scale
    first = np.concatenate([[0], np.arange(size) // 6])   # column j + 1 perturbs unknown j

    def residuals(x, factor, jacobian=False):
        """Return the residual at x under a fraction of the load (and its Jacobian)."""
        args = (factor * tensions, factor * wrench, pass_through, steps)
        if not jacobian:
            return _residuals(robot, x[:, None], *args)[0][:, 0]
        batch = np.hstack([x[:, None], x[:, None] + np.diag(delta)])
        res = _residuals(robot, batch, *args, first)[0]
        return res[:, 0], (res[:, 1:] - res[:, :1]) / delta

    x, done, increment, total = np.zeros(size), 0.0, 1.0, 0
    with np.errstate(over='ignore', invalid='ignore', divide='ignore'):
        for _ in range(max_load_steps):
            factor = min(1.0, done + increment)
            solved, iterations = _newton(lambda y, j=False: residuals(y, factor, j), x, scale,
                                         tolerance, max_iterations)
            total += iterations
            if solved is None:
                increment *= 0.5
                continue
            x, done, increment = solved, factor, 2.0 * increment
            if done == 1.0:
                res, positions, rotations = _residuals(robot, x[:, None], tensions, wrench,
                                                       pass_through, steps)
                return RodSolution(positions[..., 0], rotations[..., 0],
                                   float(np.linalg.norm(res)), total)
    raise RuntimeError(f'the subsegment Cosserat rod did not converge: load factor {done:g} '
                       f'reached in {max_load_steps} load steps')


def _newton(residuals, x, scale, tolerance, max_iterations):
    """
    Run Newton's method with a backtracking line search from ``x``.

    Parameters
    ----------
    residuals : callable
        ``residuals(x)`` -> (6N,) residual; ``residuals(x, True)`` -> residual and Jacobian.
    x : (6N,) ndarray
        The start.
    scale, tolerance, max_iterations
        As in :func:`solve_rod`.

    Returns
    -------
    x : (6N,) ndarray or None
        The solution, None if Newton failed.
    iterations : int

    """
    r0, jacobian = residuals(x, True)
    for iteration in range(1, max_iterations + 1):
        if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(jacobian))):
            return None, iteration
        try:
            dx = solve(jacobian, -r0)
        except LinAlgError:
            return None, iteration
        if np.max(np.abs(dx) / scale) < tolerance:
            return x + dx, iteration
        norm0, t = np.linalg.norm(r0), 1.0
        r1, next_jacobian = residuals(x + dx, True)     # the full step, with its Jacobian
        while not np.linalg.norm(r1) < (1.0 - 1e-4 * t) * norm0:    # False for NaN too
            t *= 0.5                                    # backtracking
            if t < 1e-4:
                return None, iteration
            r1, next_jacobian = residuals(x + t * dx), None
        x = x + t * dx
        r0, jacobian = (r1, next_jacobian) if next_jacobian is not None else residuals(x, True)
    return None, max_iterations
