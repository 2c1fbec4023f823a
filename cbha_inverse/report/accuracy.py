"""
``cbha_report accuracy``: error against run time for each model choice.

Every error is measured against a reference nobody tuned:

(a) links per segment of a Timoshenko beam chain vs the exact inextensible elastica
    (:func:`cbha_inverse.report.references.elastica_tip`);
(b) the same 8-segment cylinder body as a beam chain, as a chain of condensed segments and as a
    full FE model (linear tip compliance; St Venant-Kirchhoff large bending), with the chain's
    speed-up over the full FE (:mod:`cbha_inverse.fem.validation`);
(c) P1 / P2 and mesh size: condensation error against the finest P2 mesh vs condensation time;
(d) the CBHA inverse tick along the paper's circle: Newton steps per tick, ``relinearize_every``
    and the QP solver; effector error = the converged static equilibrium of the commanded
    pressures (``scene.forward``) minus the target, against the tick time;
(e) closed-loop tracking RMS on the simulated CBHA (:class:`cbha_inverse.sim.plant.StaticPlant`,
    10 % softer than the model, gravity) against the per-tick compute time, for several tick
    rates and relinearisation intervals.

Writes ``accuracy.md``, ``accuracy.json`` and ``accuracy.png`` (one Pareto panel per part, each
naming its reference and the machine) to ``--output`` (default ``output/report``).

The results and how to read them: docs/stability-and-accuracy.md.
"""

import argparse
import json
from pathlib import Path
import platform
import sys
import time

from cbha_inverse.core.inverse.results import HELD_STATUSES
from cbha_inverse.core.statics import solve_static
from cbha_inverse.report.bench_inverse import circle_targets
from cbha_inverse.report.references import elastica_tip, straight_beam_chain
import numpy as np

E_MOD, NU = 1.0e6, 0.3


def _best_time(function, repeats):
    """Return (result, shortest wall time [s]) of ``repeats`` calls."""
    best, out = np.inf, None
    for _ in range(repeats):
        started = time.perf_counter()
        out = function()
        best = min(best, time.perf_counter() - started)
    return out, best


def elastica_rows(quick):
    """Return the rows of (a): beam-chain links vs the exact elastica (PL^2/EI = 3, 10)."""
    counts = (2, 4, 8, 16, 32) if quick else (2, 4, 8, 16, 32, 64, 128, 256)
    rows = []
    for alpha in (3.0, 10.0):
        exact = elastica_tip(alpha)
        moved = np.linalg.norm(exact - [1.0, 0.0])
        for n in counts:
            # slender (L/R = 500): extension and shear below 1e-5, the elastica's assumptions
            model, comp, _ = straight_beam_chain(n, 1.0, 2e9, NU, 1.0 / 500)
            force = alpha * (1.0 / comp[:, 5, 5].sum())
            res, seconds = _best_time(lambda: solve_static(
                model, tip_wrench=[0.0, force, 0.0, 0.0, 0.0, 0.0]), 1 if n > 64 else 5)
            error = float(np.linalg.norm(res.positions[-1, :2] - exact) / moved)
            rows.append({'part': 'a', 'alpha': alpha, 'links': n, 'error': error,
                         'seconds': seconds, 'converged': bool(res.converged)})
    return rows


def body_rows(quick):
    """Return the rows of (b): beam chain, condensed chain and full FE of one body."""
    from cbha_inverse.fem.segment_io import chain_from_segments
    from cbha_inverse.fem.validation import chain_tip_compliance, large_bending
    from cbha_inverse.fem.validation import linear_chain_vs_full, relative_diagonal_error
    rows = []
    n_segments, length, radius = 4, 0.02, 0.005
    size = 0.0025 if quick else 0.0018
    lin = linear_chain_vs_full(n_segments, length, radius, youngs_modulus=E_MOD,
                               poisson_ratio=NU, mesh_size=size)
    beam = straight_beam_chain(n_segments, n_segments * length, E_MOD, NU, radius)[0]
    beam_tip, beam_seconds = _best_time(lambda: chain_tip_compliance(beam), 3)
    _, chain_seconds = _best_time(
        lambda: chain_tip_compliance(chain_from_segments([lin['segment']] * n_segments)), 3)
    for model, tip, seconds in (('beam chain', beam_tip, beam_seconds),
                                ('condensed chain', lin['chain'], chain_seconds),
                                ('full FE', lin['full'], lin['full_seconds'])):
        rows.append({'part': 'b', 'case': f'linear, {n_segments} x 20 mm cylinder',
                     'model': model, 'seconds': seconds,
                     'error': float(relative_diagonal_error(tip, lin['full']).max()),
                     'speed_up': lin['full_seconds'] / seconds})
    big = large_bending(mesh_size=0.0025)
    force = big['force']
    beam = straight_beam_chain(8, 0.08, E_MOD, NU, 0.0025)[0]
    beam_res, beam_seconds = _best_time(
        lambda: solve_static(beam, tip_wrench=[0.0, 0.0, -force, 0.0, 0.0, 0.0]), 3)
    scale = np.linalg.norm(big['full_tip'] - [0.08, 0.0, 0.0])
    for model, tip, seconds in (('beam chain', beam_res.positions[-1], beam_seconds),
                                ('condensed chain', big['chain_tip'], big['chain_seconds']),
                                ('full FE', big['full_tip'], big['full_seconds'])):
        rows.append({'part': 'b', 'case': f"SVK, 8 x 10 mm, {big['tip_rotation_deg']:.0f} deg",
                     'model': model, 'seconds': seconds,
                     'error': float(np.linalg.norm(tip - big['full_tip']) / scale),
                     'speed_up': big['full_seconds'] / seconds})
    return rows


def mesh_rows(quick):
    """Return the rows of (c): P1 / P2 and mesh size of a cylinder vs the finest P2 mesh."""
    from cbha_inverse.fem.validation import cylinder_mesh_study, REFERENCE_REFINEMENT
    sizes = (0.012, 0.009, 0.006) if quick else (0.012, 0.009, 0.006, 0.004)
    _, cases = cylinder_mesh_study(0.1, 0.01, sizes, youngs_modulus=E_MOD, poisson_ratio=NU)
    return [{'part': 'c', 'order': order, 'mesh_size': size, 'error': float(error.max()),
             'seconds': seg.timings['total'], 'nodes': seg.n_nodes,
             'reference_mesh_size': REFERENCE_REFINEMENT * min(sizes)}
            for order, size, seg, error in cases]


def tick_rows(quick):
    """Return the rows of (d): CBHA tick variants, static effector error vs tick time."""
    from cbha_inverse.scene import load_scene
    scene = load_scene('cbha')
    n_ticks = 300 if quick else 1500                 # 1500 ticks = one paper circle at 100 Hz
    targets = circle_targets(scene.workspace_center, 0.06, n_ticks, n_ticks)
    variants = [('active_set', 1, 1), ('active_set', 2, 1), ('active_set', 1, 2),
                ('active_set', 1, 5), ('active_set', 1, 10), ('proxsuite', 1, 1)]
    if not quick:
        # the paper's projected Gauss-Seidel costs ~10 ms per tick here: full run only
        variants += [('active_set', 3, 1), ('proxsuite', 1, 5), ('gauss_seidel', 1, 1)]
    rows = []
    stride = 10 if quick else 25
    for solver_name, newton_steps, relinearize in variants:
        solver = scene.make_inverse_solver(qp_solver=solver_name, newton_steps=newton_steps,
                                           relinearize_every=relinearize)
        solver.warm_up()
        for _ in range(30):                          # settle on the start of the circle
            solver.step(targets[0])
            solver.prepare()
        times, errors, state = [], [], None
        for i, target in enumerate(targets):
            started = time.perf_counter()
            out = solver.step(target)
            solver.prepare()
            times.append(time.perf_counter() - started)
            if i % stride == 0:
                truth = scene.forward(out.actuation, initial_state=state)
                state = truth.state
                errors.append(np.linalg.norm(truth.effector_positions - target))
        rows.append({'part': 'd', 'qp_solver': solver_name, 'newton_steps': newton_steps,
                     'relinearize_every': relinearize,
                     'tick_median_us': 1e6 * float(np.median(times)),
                     'tick_p99_us': 1e6 * float(np.percentile(times, 99)),
                     'error_rms_mm': 1e3 * float(np.sqrt(np.mean(np.square(errors)))),
                     'error_max_mm': 1e3 * float(np.max(errors))})
    return rows


def closed_loop_rows(quick):
    """Return the rows of (e): closed-loop tracking RMS vs the per-tick compute time."""
    from cbha_inverse.core.inverse.correction import TargetCorrector
    from cbha_inverse.sim.plant import StaticPlant
    from cbha_inverse.scene import load_scene
    model_scene = load_scene('cbha')
    plant_scene = load_scene('cbha', stiffness_scale=0.9)
    period = 0.06 * 2.0 * np.pi / 0.025                 # the paper's circle: 2.5 cm/s
    rates = (10.0, 30.0) if quick else (10.0, 30.0, 100.0)
    duration = 0.25 * period if quick else period
    rows = []
    for rate in rates:
        for relinearize in (1, 5):
            solver = model_scene.make_inverse_solver(relinearize_every=relinearize)
            solver.warm_up()
            plant = StaticPlant(plant_scene)
            # the node's 0.1 at 100 Hz, the same integral time at lower rates (at most 0.3:
            # the one-Newton-step model lags a tick, a larger gain overshoots)
            corrector = TargetCorrector(1, gain=min(0.3, 10.0 / rate))
            n_ticks = int(duration * rate)
            targets = circle_targets(model_scene.workspace_center, 0.06, n_ticks,
                                     period * rate)
            # settle at the start of the circle before measuring
            measured, times, errors = None, [], []
            for settle in range(int(rate)):
                out = solver.step(corrector.update(targets[0], measured))
                measured = plant.update(out.actuation).effector_positions
            goal = None
            for target in targets:
                started = time.perf_counter()
                held = out.status in HELD_STATUSES
                goal = corrector.update(target, measured, held,
                                        None if goal is None else goal - out.effector_positions)
                out = solver.step(goal)
                solver.prepare()
                times.append(time.perf_counter() - started)
                measured = plant.update(out.actuation).effector_positions
                errors.append(np.linalg.norm(measured - target))
            rows.append({'part': 'e', 'rate_hz': rate, 'relinearize_every': relinearize,
                         'tick_median_us': 1e6 * float(np.median(times)),
                         'compute_fraction': float(np.median(times) * rate),
                         'rms_mm': 1e3 * float(np.sqrt(np.mean(np.square(errors)))),
                         'max_mm': 1e3 * float(np.max(errors))})
    return rows


def _machine():
    """Return this machine's name for the figures."""
    return f'{platform.node()}, {platform.machine()}, Python {platform.python_version()}'


def _pareto_lines(ax, rows, group, groups, x, y, label, annotation):
    """
    Draw one log-log line of ``rows`` per group, each point annotated.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The panel.
    rows : list of dict
        The rows of one part.
    group : str
        Key whose value selects a line.
    groups : iterable
        The values of ``group`` drawn, in the legend's order.
    x, y : callable
        Row -> the point's coordinates.
    label, annotation : callable
        Group value -> the line's legend label; row -> the text beside its point.

    """
    for value in groups:
        sel = [r for r in rows if r[group] == value]
        ax.loglog([x(r) for r in sel], [y(r) for r in sel], 'o-', label=label(value))
        for r in sel:
            ax.annotate(annotation(r), (x(r), y(r)), fontsize=7)


def _figure(rows, path):
    """Draw one Pareto panel per part (error against run time) and the headline."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    fig, grid = plt.subplots(2, 3, figsize=(17, 10))
    axes = grid.ravel()
    part = [r for r in rows if r['part'] == 'a']
    _pareto_lines(axes[0], part, 'alpha', sorted({r['alpha'] for r in part}),
                  lambda r: r['seconds'], lambda r: r['error'],
                  lambda alpha: f'PL^2/EI = {alpha:g}', lambda r: str(r['links']))
    axes[0].axhline(5e-3, color='k', lw=0.7, ls='--')
    axes[0].set(xlabel='static solve [s]', ylabel='tip error / tip displacement',
                title='(a) beam links vs exact elastica')
    part = [r for r in rows if r['part'] == 'b']
    _pareto_lines(axes[1], part, 'case', dict.fromkeys(r['case'] for r in part),
                  lambda r: r['seconds'], lambda r: max(r['error'], 1e-6),
                  str, lambda r: r['model'])
    axes[1].set(xlabel='solve [s]',
                ylabel='vs full FE: max diag compliance (linear), tip / displacement (SVK)',
                title='(b) reference: full FE of the body (drawn at 1e-6)')
    _pareto_lines(axes[2], [r for r in rows if r['part'] == 'c'], 'order', (1, 2),
                  lambda r: r['seconds'], lambda r: r['error'],
                  lambda order: f'P{order}', lambda r: f"{1e3 * r['mesh_size']:g} mm")
    axes[2].set(xlabel='condensation [s]', ylabel='max diag compliance error',
                title='(c) cylinder L/R = 10, reference: finest P2 mesh')
    part = [r for r in rows if r['part'] == 'd']
    for r in part:
        axes[3].loglog(r['tick_median_us'], r['error_rms_mm'], 'o')
        axes[3].annotate(f"{r['qp_solver']} N{r['newton_steps']} lin{r['relinearize_every']}",
                         (r['tick_median_us'], r['error_rms_mm']), fontsize=7)
    axes[3].set(xlabel='tick median [us]', ylabel='RMS |static tip - target| [mm]',
                title='(d) CBHA tick, 60 mm circle; reference: converged statics')
    _pareto_lines(axes[4], [r for r in rows if r['part'] == 'e'], 'relinearize_every', (1, 5),
                  lambda r: r['compute_fraction'], lambda r: r['rms_mm'],
                  lambda every: f'relinearize_every {every}', lambda r: f"{r['rate_hz']:g} Hz")
    axes[4].set(xlabel='compute budget: tick median x rate [fraction of one core]',
                ylabel='tracking RMS |plant tip - target| [mm]',
                title='(e) closed loop on the simulated CBHA (plant 10 % softer)')
    axes[5].axis('off')
    axes[5].text(0.0, 1.0, '\n'.join(_headline_lines(rows, digits=3)), va='top', fontsize=8,
                 family='monospace', transform=axes[5].transAxes)
    for ax in axes[:5]:
        ax.grid(True, which='both', lw=0.3)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.suptitle(f'cbha_report accuracy — error against run time; machine: {_machine()}',
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _cell(value, digits=4):
    """Return a table or headline value as text (floats to ``digits`` significant digits)."""
    return f'{value:.{digits}g}' if isinstance(value, float) else str(value)


def _table(rows, keys):
    """Return the lines of a Markdown table of ``keys`` over ``rows``."""
    lines = ['| ' + ' | '.join(keys) + ' |', '|' + '---|' * len(keys)]
    lines += ['| ' + ' | '.join(_cell(r[k]) for k in keys) + ' |' for r in rows]
    return lines


def _headline_lines(rows, digits=4):
    """Return the headline of a run as ``key: value`` lines."""
    return [f'{key}: {_cell(value, digits)}' for key, value in headline(rows).items()]


def headline(rows):
    """Return the headline numbers (dict) of a run."""
    out = {}
    for alpha in (3.0, 10.0):
        fine = [r['links'] for r in rows if r['part'] == 'a' and r['alpha'] == alpha
                and r['error'] <= 5e-3]
        out[f'links_for_0.5pct_elastica_alpha_{alpha:g}'] = min(fine) if fine else None
    for r in rows:
        if r['part'] == 'b' and r['model'] != 'full FE':
            out[f"{r['case']}: {r['model']} error"] = r['error']
            out[f"{r['case']}: {r['model']} speed-up"] = r['speed_up']
    for r in rows:
        if r['part'] == 'd':
            out[f"tick {r['qp_solver']} N{r['newton_steps']} lin{r['relinearize_every']}"] = (
                f"{r['tick_median_us']:.0f} us, RMS {r['error_rms_mm']:.3f} mm")
    return out


def write_report(rows, out_dir, elapsed, quick):
    """Write accuracy.md, accuracy.json and accuracy.png."""
    out_dir.mkdir(parents=True, exist_ok=True)
    _figure(rows, out_dir / 'accuracy.png')
    lines = ['# Error against run time', '',
             f'{"quick" if quick else "full"} run, {elapsed:.0f} s on {_machine()}.', '',
             '![accuracy](accuracy.png)', '', '## (a) beam links vs the exact elastica', '']
    lines += _table([r for r in rows if r['part'] == 'a'],
                    ['alpha', 'links', 'error', 'seconds', 'converged'])
    lines += ['', '## (b) beam chain, condensed chain, full FE (reference: full FE)', '']
    lines += _table([r for r in rows if r['part'] == 'b'],
                    ['case', 'model', 'error', 'seconds', 'speed_up'])
    lines += ['', '## (c) element order and mesh size (reference: finest P2)', '']
    lines += _table([r for r in rows if r['part'] == 'c'],
                    ['order', 'mesh_size', 'nodes', 'error', 'seconds'])
    lines += ['', '## (d) CBHA inverse tick (reference: converged static equilibrium)', '']
    lines += _table([r for r in rows if r['part'] == 'd'],
                    ['qp_solver', 'newton_steps', 'relinearize_every', 'tick_median_us',
                     'tick_p99_us', 'error_rms_mm', 'error_max_mm'])
    lines += ['', '## (e) closed loop on the simulated CBHA (plant 10 % softer)', '']
    lines += _table([r for r in rows if r['part'] == 'e'],
                    ['rate_hz', 'relinearize_every', 'tick_median_us', 'compute_fraction',
                     'rms_mm', 'max_mm'])
    lines += ['', '## Headline', '']
    lines += [f'- {line}' for line in _headline_lines(rows)]
    (out_dir / 'accuracy.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    (out_dir / 'accuracy.json').write_text(json.dumps(
        {'quick': quick, 'elapsed_s': elapsed, 'machine': _machine(), 'rows': rows,
         'headline': headline(rows)}, indent=1), encoding='utf-8')


def main(argv=None):
    """
    Run the accuracy report.

    Parameters
    ----------
    argv : list of str, optional
        ``[--quick] [--output DIR]``.

    Returns
    -------
    int
        0.

    """
    parser = argparse.ArgumentParser(prog='cbha_report accuracy',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='fewer, smaller cases (test suite)')
    parser.add_argument('--output', default='output/report', help='output directory')
    args = parser.parse_args(argv)
    started = time.perf_counter()
    rows = []
    for part in (elastica_rows, body_rows, mesh_rows, tick_rows, closed_loop_rows):
        part_started = time.perf_counter()
        rows += part(args.quick)
        print(f'{part.__name__}: {time.perf_counter() - part_started:.1f} s', flush=True)
    elapsed = time.perf_counter() - started
    write_report(rows, Path(args.output), elapsed, args.quick)
    print('\n'.join(_headline_lines(rows)))
    print(f'{elapsed:.1f} s; written to {args.output}/accuracy.md')
    return 0


if __name__ == '__main__':
    sys.exit(main())
