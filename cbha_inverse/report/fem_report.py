"""
Console script ``cbha_fem_report``: condensation accuracy and run time.

Tables (Markdown on stdout, CSV and a PNG plot with ``--output-dir``):

1. cylinder condensation, P1 / P2 and mesh size: error against Timoshenko (slender L/R = 10) and
   against the finest P2 mesh, with run time; the stubby 20 mm x R10 mm case;
2. CBHA bellows segment, P1 / P2 and mesh size: error against the finest P2 mesh, run time;
3. chain of 4 condensed 20 mm cylinders against the linear full FE of the 80 mm body;
4. large bending: chain (core.solve_static) against the nonlinear St Venant-Kirchhoff body;
5. CBHA stacks: chain against the full linear FE of n stacked bellows segments, speed-up.

The results and how to read them: docs/stability-and-accuracy.md.
"""

import argparse
from pathlib import Path
import sys
import time

from cbha_inverse.fem.segment_spec import cbha_geometry_path, read_segment_spec
from cbha_inverse.fem.validation import relative_diagonal_error
import numpy as np

E_MOD, NU = 1.0e6, 0.3


def _row(label, order, size, compliance, reference, seconds, extra=None):
    err = relative_diagonal_error(compliance, reference)
    row = {'case': label, 'order': order, 'mesh_size_mm': round(size * 1e3, 3),
           'max_diag_error_pct': float(100 * err.max()), 'seconds': float(seconds)}
    row.update(extra or {})
    return row


def cylinder_table(quick):
    """
    Return rows of the cylinder condensation table.

    Parameters
    ----------
    quick : bool
        Fewer and coarser meshes.

    Returns
    -------
    list of dict
        One row per (case, order, mesh size).

    """
    from cbha_inverse.core.links import timoshenko_compliance
    from cbha_inverse.fem.condensation import condense_cylinder
    from cbha_inverse.fem.validation import cylinder_mesh_study
    sizes = [0.006, 0.004] if quick else [0.008, 0.006, 0.004, 0.003]
    beam = timoshenko_compliance(0.1, E_MOD, NU, 0.01)
    rows = []
    _, cases = cylinder_mesh_study(0.1, 0.01, sizes, youngs_modulus=E_MOD, poisson_ratio=NU)
    for order, size, seg, err_fe in cases:
        rows.append(_row('slender L/R=10 vs Timoshenko', order, size, seg.compliance, beam,
                         seg.timings['total'],
                         {'vs_finest_P2_pct': float(100 * err_fe.max()), 'nodes': seg.n_nodes}))
    stubby = condense_cylinder(0.02, 0.01, youngs_modulus=E_MOD, poisson_ratio=NU,
                               mesh_size=0.003)
    ratio = np.diag(stubby.compliance) / np.diag(timoshenko_compliance(0.02, E_MOD, NU, 0.01))
    rows.append(_row('stubby 20 mm x R10 vs Timoshenko', 2, 0.003, stubby.compliance,
                     timoshenko_compliance(0.02, E_MOD, NU, 0.01), stubby.timings['total'],
                     {'diag_ratio_fe_over_beam': np.round(ratio, 4).tolist(),
                      'nodes': stubby.n_nodes}))
    return rows


def bellows_table(quick):
    """
    Return rows of the CBHA bellows segment table (error against the finest P2 mesh).

    Parameters
    ----------
    quick : bool
        Skip the expensive reference and fine meshes.

    Returns
    -------
    list of dict
        One row per (order, mesh size).

    """
    from cbha_inverse.fem.condensation import condense_bellows
    spec = read_segment_spec(cbha_geometry_path())
    sizes = [0.001, 0.0008] if quick else [0.001, 0.0008, 0.000625, 0.0005]
    ref_size = 0.000625 if quick else 0.00035
    reference = condense_bellows(spec, mesh_size=ref_size)
    rows = []
    for order in (1, 2):
        for size in sizes:
            seg = condense_bellows(spec, mesh_size=size, order=order)
            rows.append(_row('CBHA segment vs finest P2', order, size, seg.compliance,
                             reference.compliance, seg.timings['total'],
                             {'nodes': seg.n_nodes, 'reference_mm': ref_size * 1e3}))
    rows.append(_row('CBHA segment reference', 2, ref_size, reference.compliance,
                     reference.compliance, reference.timings['total'],
                     {'nodes': reference.n_nodes}))
    return rows


def chain_tables(quick):
    """
    Return rows comparing chains of condensed segments with full FE bodies.

    Parameters
    ----------
    quick : bool
        Skip the CBHA stacks.

    Returns
    -------
    list of dict
        Linear cylinder chain, large bending, CBHA stacks (unless quick).

    """
    from cbha_inverse.fem.validation import (bellows_chain_vs_full, large_bending,
                                             linear_chain_vs_full)
    from cbha_inverse.core.statics import solve_static
    from cbha_inverse.fem.segment_io import chain_from_segments
    rows = []
    lin = linear_chain_vs_full(4, 0.02, 0.005, youngs_modulus=E_MOD, poisson_ratio=NU,
                               mesh_size=0.0025)
    model = chain_from_segments([lin['segment']] * 4)
    t0 = time.perf_counter()
    solve_static(model, tip_wrench=[0.0, 1e-6, 1e-6, 0.0, 0.0, 0.0])
    chain_static = time.perf_counter() - t0
    rows.append({'case': '4 x 20 mm cylinder, linear, tip compliance',
                 'max_diag_error_pct': float(100 * lin['error'].max()),
                 'full_seconds': lin['full_seconds'], 'chain_seconds': chain_static,
                 'speed_up': lin['full_seconds'] / chain_static})
    big = large_bending()
    rows.append({'case': (f"8 x 10 mm cylinder, SVK tip load, {big['tip_rotation_deg']:.1f} deg "
                          'tip rotation'),
                 'tip_error_pct_of_displacement': 100 * big['error_over_displacement'],
                 'tip_error_pct_of_length': 100 * big['error_over_length'],
                 'full_seconds': big['full_seconds'], 'chain_seconds': big['chain_seconds'],
                 'speed_up': big['full_seconds'] / big['chain_seconds'],
                 'full_newton_iterations': big['full'].iterations})
    if not quick:
        spec = read_segment_spec(cbha_geometry_path())
        for n in (1, 2):
            out = bellows_chain_vs_full(spec, n)
            rows.append({'case': f'CBHA stack of {n} bellows segment(s), linear',
                         'max_diag_error_pct': float(100 * out['error'].max()),
                         'full_seconds': out['full_seconds'],
                         'chain_seconds': out['chain_seconds'],
                         'speed_up': out['full_seconds'] / out['chain_seconds'],
                         'body_dofs': out['body_dofs']})
    return rows


def markdown(rows, title):
    """
    Format rows as a Markdown table.

    Parameters
    ----------
    rows : list of dict
        Table rows (union of keys are the columns).
    title : str
        Heading.

    Returns
    -------
    str
        The table.

    """
    keys = []
    for row in rows:
        keys += [k for k in row if k not in keys]

    def fmt(value):
        if isinstance(value, float):
            return f'{value:.4g}'
        return str(value)
    lines = [f'### {title}', '', '| ' + ' | '.join(keys) + ' |',
             '|' + '---|' * len(keys)]
    lines += ['| ' + ' | '.join(fmt(r.get(k, '')) for k in keys) + ' |' for r in rows]
    return '\n'.join(lines) + '\n'


def plot(rows, path):
    """
    Save the error-against-run-time plot of the condensation tables.

    Parameters
    ----------
    rows : list of dict
        Rows with 'seconds', 'max_diag_error_pct' / 'vs_finest_P2_pct', 'case', 'order'.
    path : path-like
        PNG file.

    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for case, key in (('slender L/R=10 vs Timoshenko', 'vs_finest_P2_pct'),
                      ('CBHA segment vs finest P2', 'max_diag_error_pct')):
        for order, marker in ((1, 'o'), (2, 's')):
            sel = [r for r in rows if r['case'] == case and r['order'] == order]
            if sel:
                ax.loglog([r['seconds'] for r in sel], [max(r[key], 1e-4) for r in sel],
                          marker=marker, label=f'{case.split(" ")[0]} P{order}')
    ax.set_xlabel('condensation time [s]')
    ax.set_ylabel('max diagonal error of C [%]')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(str(path), dpi=120)
    plt.close(fig)


def main(argv=None):
    """
    Run the ``cbha_fem_report`` console script.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.

    """
    parser = argparse.ArgumentParser(prog='cbha_fem_report', description=__doc__.split('\n')[1])
    parser.add_argument('--quick', action='store_true', help='coarse meshes only (about 1 min)')
    parser.add_argument('--output-dir', default=None, help='write CSV tables and a PNG plot')
    args = parser.parse_args(argv)
    tables = [('Cylinder condensation: P1/P2, mesh size, error, time', cylinder_table),
              ('CBHA bellows segment: P1/P2, mesh size, error, time', bellows_table),
              ('Chain of condensed segments vs full FE (speed-up at equal answer)',
               chain_tables)]
    all_rows = []
    out_dir = Path(args.output_dir) if args.output_dir else None
    if out_dir:
        out_dir.mkdir(parents=True, exist_ok=True)
    for index, (title, builder) in enumerate(tables, start=1):
        rows = builder(args.quick)
        all_rows += rows
        text = markdown(rows, title)
        print(text)
        sys.stdout.flush()
        if out_dir:
            (out_dir / f'fem_table_{index}.md').write_text(text)
    if out_dir:
        plot(all_rows, out_dir / 'fem_error_vs_time.png')
        print(f'written: {out_dir}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
