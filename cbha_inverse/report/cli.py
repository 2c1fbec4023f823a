"""
``cbha_report``: one entry point for the package's benchmarks and reports.

Each sub-command runs the report of one part and prints its table; ``all`` runs them in turn.
"""

import argparse
import importlib
import sys

#: sub-command -> (module with ``main(argv)``, what it reports)
REPORTS = {
    'core': ('cbha_inverse.report.bench_core',
             'block-tridiagonal solver vs LAPACK banded/dense, static-solve times'),
    'inverse': ('cbha_inverse.report.bench_inverse',
                'inverse-model tick time per scene with its breakdown'),
    'estimator': ('cbha_inverse.report.bench_estimator',
                  'shape-estimator update time and tip accuracy on the CBHA string pots'),
    'fem': ('cbha_inverse.report.fem_report',
            'condensation error against run time, chain vs full FE'),
    'stability': ('cbha_inverse.report.stability',
                  'numerical stability on stiff and extreme cases ([--quick] [--output DIR])'),
    'accuracy': ('cbha_inverse.report.accuracy',
                 'error against run time, Pareto plots ([--quick] [--output DIR])'),
    'rao2021': ('cbha_inverse.report.benchmark_rao2021',
                'tip positions against the reference model of Rao et al. 2021 ([--refine])'),
    'touch': ('cbha_inverse.report.touch',
              "touch with a bounded force: the plant's measured contact force, tangential drift"),
}
GROUPS = {'bench': ('core', 'inverse', 'estimator'),
          'all': ('core', 'inverse', 'estimator', 'fem', 'stability', 'accuracy', 'rao2021')}
#: reports that take the common ``[--quick] [--output DIR]`` (passed on by a group run)
COMMON_ARGS = ('stability', 'accuracy')


def main(argv=None):
    """
    Run one report, a group of reports, or all of them.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``); arguments after the report name are
        passed to that report (in a group, such as ``all --quick --output DIR``, to the reports
        of ``COMMON_ARGS`` only).

    Returns
    -------
    int
        0 on success, the first non-zero exit code of a report otherwise.

    """
    parser = argparse.ArgumentParser(
        prog='cbha_report', description=__doc__.strip().splitlines()[0],
        epilog='\n'.join(f'{name}: {text}' for name, (_, text) in REPORTS.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('report', choices=sorted(REPORTS) + sorted(GROUPS))
    parser.add_argument('report_args', nargs=argparse.REMAINDER,
                        help='arguments passed to the report (single report only)')
    args = parser.parse_args(argv)
    names = GROUPS.get(args.report, (args.report,))
    if len(names) > 1 and {'-h', '--help'} & set(args.report_args):
        # a group passes its arguments on to reports: its --help is its own, and runs nothing
        print(f'usage: cbha_report {args.report} [--quick] [--output DIR]\n\nruns, in turn:')
        for name in names:
            print(f'  {name}: {REPORTS[name][1]}')
        print('\n`cbha_report <name> --help` describes the arguments of one report.')
        return 0
    for name in names:
        module_name, text = REPORTS[name]
        print(f'== {name}: {text}', flush=True)
        report_args = (args.report_args if len(names) == 1 or name in COMMON_ARGS else [])
        code = importlib.import_module(module_name).main(report_args)
        if code:
            return code
    return 0


if __name__ == '__main__':
    sys.exit(main())
