"""
``cbha_report touch``: touch with a bounded force, measured on the simulated plant.

The CBHA of ``cbha_table`` is given a contact target on its table (``docs/touch.md``): a point
of the table below a tangential target near its rest tip, the table's normal, force bounds. The
inverse (the scene's model) runs open loop on the core plant
(:class:`cbha_inverse.sim.plant.StaticPlant`, the scene 10 % softer, penalty contact); the
report prints, at steady state, the force the model predicts, the plant's measured normal force
on the tip's sphere and the tip's tangential drift (its distance, in the table's plane, from
the tangential target), and whether the measured force lies within the bounds.
"""

import argparse
import sys

from cbha_inverse.core.inverse.touch import measured_touch_force
import numpy as np

TABLE_NORMAL = np.array([0.0, 0.0, 1.0])
"""The table's outward normal in ``cbha_table`` (a plane: its free side is +z)."""
WALL_NORMAL = np.array([-1.0, 0.0, 0.0])
"""The outward normal of a wall in front of the tip (a plane turned by pitch -90°)."""
CASES = (('table', 0.0, 0.0, (0.2, 0.4), 0.0), ('wall', 0.005, 0.0, (0.1, 0.3), 0.0),
         ('wall', 0.005, 0.0, (0.5, 1.5), 0.0), ('wall', 0.005, 0.01, (0.5, 1.5), 0.0),
         ('wall', 0.005, 0.0, (0.5, 1.5), 0.1))
"""Cases: the surface; for the table nothing, for the wall its distance from the rest tip's
sphere [m]; the tangential target's offset from the rest tip along y [m]; the force bounds [N];
the closed loop's gain (0: open loop)."""


def wall_in_front(tip, radius, distance):
    """
    Return a wall (a plane, outward normal -x) ``distance`` in front of a tip sphere.

    Parameters
    ----------
    tip : (3,) ndarray  [m]
        The sphere's centre.
    radius : float  [m]
        Its radius.
    distance : float  [m]
        From the sphere's front to the wall.

    Returns
    -------
    cbha_inverse.core.obstacles.Obstacle

    """
    from cbha_inverse.core.obstacles import Obstacle
    from cbha_inverse.core.so3 import so3_exp
    return Obstacle('wall', 'plane', [tip[0] + radius + distance, 0.0, 0.0],
                    so3_exp(np.array([0.0, -0.5 * np.pi, 0.0])))


def touch_run(model_scene, plant_scene, point, normal, force_bounds, ticks=60, effector=0,
              obstacles=None, gain=0.0):
    """
    Run the inverse with a contact target on the plant; return its last tick.

    Parameters
    ----------
    model_scene : cbha_inverse.scene.Scene
        The inverse's scene (its obstacles and collision spheres).
    plant_scene : cbha_inverse.scene.Scene
        The plant's (with the model error wanted, e.g. ``stiffness_scale=0.9``).
    point : (3,) array_like  [m]
        The contact point ``s``; also the effector's (tangential) target.
    normal : (3,) array_like
        The surface's outward unit normal.
    force_bounds : (2,) array_like  [N]
        ``[f_min, f_max]``.
    ticks : int
        Ticks to run.
    effector : int
        The touching effector.
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle, optional
        The obstacles of the inverse and the plant (default: each scene's).
    gain : float
        The closed loop's integral gain on the plant's effector positions
        (:class:`~cbha_inverse.core.inverse.correction.TargetCorrector`, the touching
        effector's tangential error only); 0: open loop.

    Returns
    -------
    dict
        ``status``, ``predicted_n`` (the model's force), ``measured_n`` (the plant's normal
        force on the effector's sphere), ``drift_mm`` (the plant effector's distance from the
        tangential target in the surface's plane), ``settle_n`` (the largest change of the
        measured force over the last 10 ticks), ``warnings``.

    """
    from cbha_inverse.core.inverse.correction import TargetCorrector
    from cbha_inverse.core.inverse.results import HELD_STATUSES
    from cbha_inverse.sim.plant import StaticPlant
    point, normal = np.asarray(point, dtype=float), np.asarray(normal, dtype=float)
    solver = model_scene.make_inverse_solver()
    solver.warm_up()
    plant = StaticPlant(plant_scene)
    if obstacles is not None:
        solver.set_obstacles(obstacles)
        plant.set_obstacles(obstacles)
    touch = solver.set_touch(effector, point, normal, force_bounds)
    targets = model_scene.rest_effector_positions.copy()
    targets[effector] = point
    corrector = TargetCorrector(targets.shape[0], gain=gain)
    corrector.set_touch_normal(effector, normal)
    measured, positions, result = [], None, None
    for _ in range(ticks):
        held = result is not None and result.status in HELD_STATUSES
        goal = corrector.update(targets, positions, held)
        result = solver.step(goal)
        solver.prepare()
        positions = plant.update(result.actuation).effector_positions
        measured.append(measured_touch_force(plant.contacts, touch.frame, normal))
    tip = positions[effector]
    away = tip - point
    drift = np.linalg.norm(away - normal * (normal @ away))
    return {'status': result.status, 'predicted_n': float(result.touch_forces[effector]),
            'measured_n': measured[-1], 'drift_mm': 1e3 * float(drift),
            'settle_n': float(np.ptp(measured[-10:])), 'warnings': result.warnings}


def main(argv=None):
    """
    Print the touch cases' steady state (module docstring); return 1 if one leaves its bounds.

    Parameters
    ----------
    argv : list of str, optional
        ``[--ticks N] [--stiffness-scale S]`` (default ``sys.argv[1:]``).

    Returns
    -------
    int

    """
    from cbha_inverse.scene import load_scene
    parser = argparse.ArgumentParser(prog='cbha_report touch', description=__doc__.strip()
                                     .splitlines()[0])
    parser.add_argument('--ticks', type=int, default=60, help='ticks per case (default 60)')
    parser.add_argument('--stiffness-scale', type=float, default=0.9,
                        help="the plant's stiffness over the model's (default 0.9)")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    model_scene = load_scene('cbha_table')
    plant_scene = load_scene('cbha_table', stiffness_scale=args.stiffness_scale)
    rest = model_scene.rest_effector_positions[0]
    radius = model_scene.collision.radii[-1]
    print(f'cbha_table, plant stiffness x {args.stiffness_scale}, {args.ticks} ticks; contact '
          'target on the table (normal +z) or on a wall in front of the tip (normal -x)')
    print('| surface | target - rest tip, y [mm] | bounds [N] | loop gain | status | model [N] '
          '| plant [N] | within | drift [mm] | last 10 ticks [N] |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    failed = 0
    for surface, distance, dy, bounds, gain in CASES:
        obstacles = None
        if surface == 'table':
            normal = TABLE_NORMAL
            point = np.array([rest[0], rest[1] + dy, model_scene.obstacles[0].position[2]])
        else:
            normal = WALL_NORMAL
            wall = wall_in_front(rest, radius, distance)
            obstacles = model_scene.obstacles + (wall,)
            point = np.array([wall.position[0], rest[1] + dy, rest[2]])
        row = touch_run(model_scene, plant_scene, point, normal, bounds, args.ticks,
                        obstacles=obstacles, gain=gain)
        within = bounds[0] <= row['measured_n'] <= bounds[1]
        failed += not within
        name = surface if surface == 'table' else f'wall {1e3 * distance:g} mm ahead'
        print(f'| {name} | {1e3 * dy:.0f} | [{bounds[0]:g}, {bounds[1]:g}] | {gain:g} '
              f"| {row['status']} | {row['predicted_n']:.4f} | {row['measured_n']:.4f} "
              f"| {'yes' if within else 'NO'} | {row['drift_mm']:.3f} "
              f"| {row['settle_n']:.1e} |")
        for warning in row['warnings']:
            print(f'  warning: {warning}')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
