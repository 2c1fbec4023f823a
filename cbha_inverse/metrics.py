"""
Tracking metrics and plots of closed/open-loop runs (used by ``cbha_demo``; no ROS).

The tip error at a tip sample is the distance to the target interpolated (linearly, per axis)
at the tip's time stamp; RMS and max are taken over the samples whose stamps lie in the moving
part of the trajectory.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrackingErrors:
    """
    Tip-to-target errors of one run.

    Attributes
    ----------
    times : (N,) ndarray  [s]
        Tip sample stamps used.
    errors : (N,) ndarray  [m]
        Distances tip - target.
    rms : float  [m]
        Root mean square of ``errors``.
    maximum : float  [m]
        Largest error.
    goals : (N, 3) ndarray  [m]
        The target at each sample (interpolated at its stamp).

    """

    times: np.ndarray
    errors: np.ndarray
    rms: float
    maximum: float
    goals: np.ndarray


def tracking_errors(target_times, targets, tip_times, tips, start, end):
    """
    Compare tip samples with the target path.

    Parameters
    ----------
    target_times : (T,) array_like  [s]
        Target stamps (increasing).
    targets : (T, 3) array_like  [m]
        Targets.
    tip_times : (N,) array_like  [s]
        Tip stamps.
    tips : (N, 3) array_like  [m]
        Tip positions.
    start, end : float  [s]
        Window of the comparison (e.g. the moving part of the lap).

    Returns
    -------
    TrackingErrors
        Errors in the window.

    Raises
    ------
    ValueError
        If fewer than 2 targets or no tip sample lie in the window.

    """
    target_times = np.asarray(target_times, dtype=float)
    targets = np.asarray(targets, dtype=float).reshape(-1, 3)
    tip_times = np.asarray(tip_times, dtype=float)
    tips = np.asarray(tips, dtype=float).reshape(-1, 3)
    inside = ((tip_times >= max(start, target_times[0] if target_times.size else np.inf))
              & (tip_times <= min(end, target_times[-1] if target_times.size else -np.inf)))
    if target_times.size < 2 or not np.any(inside):
        raise ValueError('no tip sample inside the target window')
    goal = np.stack([np.interp(tip_times[inside], target_times, targets[:, axis])
                     for axis in range(3)], axis=1)
    errors = np.linalg.norm(tips[inside] - goal, axis=1)
    return TrackingErrors(tip_times[inside], errors, float(np.sqrt(np.mean(errors ** 2))),
                          float(np.max(errors)), goal)


def unblocked_errors(tracking, obstacles, distance, settle_time):
    """
    Return the tracking errors of the samples whose targets the obstacles leave free.

    A sample is *blocked* when its target lies closer than ``distance`` to an obstacle (the
    target point's signed distance, :meth:`cbha_inverse.core.obstacles.Obstacle.signed_distance`):
    there the obstacle may hold the arm off its target. A sample up to ``settle_time`` after a
    blocked one is *settling*: the tip catches up once the obstacle lets it go. The rest is the
    unblocked part.

    Parameters
    ----------
    tracking : TrackingErrors
        A run's errors (:func:`tracking_errors`).
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles.
    distance : float  [m]
        Targets closer than this to an obstacle are blocked (e.g. the tip's collision radius
        plus the obstacle margin and a few millimetres for the neighbouring spheres).
    settle_time : float  [s]
        How long after a blocked sample the samples are left out.

    Returns
    -------
    errors : TrackingErrors
        The unblocked samples' errors, RMS and maximum.
    kept : (N,) ndarray of bool
        Which samples of ``tracking`` are unblocked.

    Raises
    ------
    ValueError
        If no sample is unblocked.

    """
    goals = np.asarray(tracking.goals, dtype=float).reshape(-1, 3)
    gaps = np.full(len(goals), np.inf)
    for obstacle in obstacles:
        gaps = np.minimum(gaps, obstacle.signed_distance(goals).distance)
    blocked_times = tracking.times[gaps < distance]
    # the latest blocked sample at or before each sample (-inf: none)
    before = np.searchsorted(blocked_times, tracking.times, side='right')
    last_blocked = np.where(before > 0, blocked_times[np.maximum(before - 1, 0)], -np.inf)
    kept = tracking.times - last_blocked > settle_time
    if not np.any(kept):
        raise ValueError('every sample is blocked or settling')
    errors = tracking.errors[kept]
    return TrackingErrors(tracking.times[kept], errors, float(np.sqrt(np.mean(errors ** 2))),
                          float(np.max(errors)), goals[kept]), kept


TRANSIENT_FACTOR = 3.0
"""A start-up transient: errors above this many times the settled (median) error."""


def transient_end(times, errors):
    """
    Return when the start-up transient of a run ends.

    The settled error is the median error of the run's second half; the transient ends after the
    last sample of the first half whose error exceeds :data:`TRANSIENT_FACTOR` times it (the
    run's start when there is none). Later excursions stay in the score.

    Parameters
    ----------
    times : (N,) array_like  [s]
        Sample times (increasing).
    errors : (N,) array_like  [m]
        Tracking errors.

    Returns
    -------
    float  [s]
        The first time of the settled run.

    """
    times = np.asarray(times, dtype=float)
    errors = np.asarray(errors, dtype=float)
    half = times.size // 2
    if half == 0:
        return float(times[0]) if times.size else 0.0
    settled = np.median(errors[half:])
    above = np.flatnonzero(errors[:half] > TRANSIENT_FACTOR * settled)
    return float(times[above[-1] + 1]) if above.size else float(times[0])


def cross_track_errors(path, tips):
    """
    Return the distance of each tip sample to a path polyline (timing ignored).

    Parameters
    ----------
    path : (T, 3) array_like  [m]
        The path's points in order (e.g. the targets of a lap), at least 2.
    tips : (N, 3) array_like  [m]
        Tip positions.

    Returns
    -------
    (N,) ndarray  [m]
        Distance of each tip to the nearest segment of the polyline.

    """
    path = np.asarray(path, dtype=float).reshape(-1, 3)
    tips = np.asarray(tips, dtype=float).reshape(-1, 3)
    if len(path) < 2:
        raise ValueError('a path needs at least 2 points')
    start, direction = path[:-1], np.diff(path, axis=0)
    length2 = np.maximum(np.sum(direction ** 2, axis=1), 1e-300)
    out = np.empty(len(tips))
    for i, tip in enumerate(tips):
        along = np.clip(np.sum((tip - start) * direction, axis=1) / length2, 0.0, 1.0)
        out[i] = np.sqrt(np.min(np.sum((start + along[:, None] * direction - tip) ** 2, axis=1)))
    return out


def plot_runs(runs, path):
    """
    Plot target vs tip in the y-z plane, one panel per run, into a PNG.

    Parameters
    ----------
    runs : list of dict
        Each with ``title`` (str), ``targets`` (T, 3), ``tips`` (N, 3) [m], ``rms`` [m], and
        optionally ``tip_label`` (the legend of the tips, default ``tip (plant)``).
    path : str or os.PathLike
        Output PNG.

    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    columns = min(2, len(runs))
    rows = int(np.ceil(len(runs) / columns))
    figure, axes = plt.subplots(rows, columns, figsize=(5.0 * columns, 4.6 * rows),
                                squeeze=False)
    for axis, run in zip(axes.flat, runs):
        targets = np.asarray(run['targets']) * 1e3
        tips = np.asarray(run['tips']) * 1e3
        axis.plot(targets[:, 1], targets[:, 2], 'k--', lw=1.0, label='target')
        axis.plot(tips[:, 1], tips[:, 2], '-', color='tab:red', lw=1.2,
                  label=run.get('tip_label', 'tip (plant)'))
        axis.set_title(f"{run['title']}: RMS {run['rms'] * 1e3:.2f} mm")
        axis.set_xlabel('y [mm]')
        axis.set_ylabel('z [mm]')
        axis.set_aspect('equal', adjustable='datalim')
        axis.grid(True, lw=0.3)
        axis.legend(loc='upper right', fontsize=8)
    for axis in list(axes.flat)[len(runs):]:
        axis.set_visible(False)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
