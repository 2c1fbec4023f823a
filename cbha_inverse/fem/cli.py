"""
Console script ``condense_segment``: geometry YAML -> condensed segment YAML (+ cavity surfaces).

Usage: ``condense_segment [GEOMETRY] [--output FILE | --output-dir DIR] [--order 2]
[--mesh-size 0.0005] [--force]``. The segment YAML ``<name>.yaml``, named after the geometry's
``name:`` field (the file stem for a ``.geo`` file), and its cavity surfaces go to ``--output`` or
``--output-dir``, else next to the geometry file; never into the package's own data (the default
geometry ``meshes/cbha_segment_geometry.yaml``, ``name: cbha_segment``, of an install): for
those, into the current directory. Same inputs (sha256 of the geometry file, the mesh
parameters and the package version) reuse the existing file, which is said on stdout. A broken
geometry file prints one line naming the file and the key, exit code 2.
"""

import argparse
from pathlib import Path
import sys

from cbha_inverse import __version__
from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.fem.segment_spec import cbha_geometry_path, read_segment_spec
from cbha_inverse.paths import share_dir
import numpy as np

PROGRAM = 'condense_segment'


def _parser():
    parser = argparse.ArgumentParser(
        prog='condense_segment',
        description='Condense a volumetric FE segment onto its two vertebra frames (6x6 C).',
        epilog='<name> is the name: field of a geometry YAML (the file stem of a .geo file); '
               'a geometry of the package itself is condensed into the current directory.')
    parser.add_argument('geometry', nargs='?', default=None,
                        help='geometry YAML or .geo file (default: '
                             'meshes/cbha_segment_geometry.yaml, which gives cbha_segment.yaml)')
    output = parser.add_mutually_exclusive_group()
    output.add_argument('--output', default=None,
                        help='segment YAML to write (default: <name>.yaml next to the geometry)')
    output.add_argument('--output-dir', default=None,
                        help='directory of <name>.yaml (default: that of the geometry)')
    parser.add_argument('--order', type=int, choices=(1, 2), default=None,
                        help='element order (default: the YAML mesh.order)')
    parser.add_argument('--mesh-size', type=float, default=None,
                        help='element size in m (default: the YAML mesh.mesh_size)')
    parser.add_argument('--force', action='store_true', help='recompute even if cached')
    geo = parser.add_argument_group('for a .geo geometry (the material is not in the file)')
    geo.add_argument('--youngs-modulus', type=float, help='Pa')
    geo.add_argument('--poisson-ratio', type=float)
    geo.add_argument('--density', type=float, default=0.0, help='kg/m^3')
    geo.add_argument('--segment-length', type=float, default=None,
                     help='frame spacing in m (default: the x extent of the mesh)')
    return parser


def pressure_notes(spec, segment, cavities, pressure=150e3, n_segments=8):
    """
    Return human-readable notes on the bending per unit pressure of a bellows segment.

    Parameters
    ----------
    spec : cbha_inverse.fem.segment_spec.SegmentSpec
        The bellows segment geometry file.
    segment : CondensedSegment
        Condensed segment.
    cavities : sequence of (name, points, triangles)
        Cavity surfaces.
    pressure : float  [Pa]
        Reference pressure.
    n_segments : int
        Segments per section.

    Returns
    -------
    list of str
        Notes.

    """
    from cbha_inverse.fem.bellows import cavity_frame_wrenches
    length = spec.geometry.segment_length
    notes = []
    for name, points, triangles in cavities:
        upper = cavity_frame_wrenches(points, triangles, length)[1]
        # the caps of stacked segments cancel on interior vertebrae: a section of identical
        # segments carries the upper-frame wrench of one segment at its tip (linear estimate)
        rotation = n_segments * segment.compliance[3:, 3:] @ upper[3:]
        notes.append(
            f'cavity {name}: {upper[0]:.4e} N/Pa axial force and moment '
            f'{np.round(upper[3:], 10).tolist()} N*m/Pa at the upper frame; {pressure:.0f} Pa in '
            f'this tube bends a section of {n_segments} segments by about '
            f'{np.degrees(np.linalg.norm(rotation) * pressure):.1f} deg (linear estimate)')
    return notes


def run_geo(args, geometry, target, out):
    """
    Condense a ``.geo`` geometry (end faces on the planes of smallest and largest x).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed options (material, order, mesh size, segment length, force).
    geometry : pathlib.Path
        The ``.geo`` file.
    target : pathlib.Path
        The segment YAML to write.
    out : file-like
        Where progress is printed.

    Returns
    -------
    pathlib.Path
        The segment YAML path.

    """
    from cbha_inverse.fem.segment_io import cached_segment, inputs_sha256, write_segment
    if args.youngs_modulus is None or args.poisson_ratio is None or args.mesh_size is None:
        raise ConfigError(geometry, 'material', 'a .geo geometry needs --youngs-modulus, '
                          '--poisson-ratio and --mesh-size')
    order = args.order or 2
    material = {'name': 'cli', 'youngs_modulus': args.youngs_modulus,
                'poisson_ratio': args.poisson_ratio, 'density': args.density}
    sha = inputs_sha256(geometry, order, args.mesh_size,
                        version=f'{__version__}|{material}|{args.segment_length}')
    if not args.force and cached_segment(target, sha):
        print(f'{target}: cached (same inputs, sha256 {sha[:12]}), not recomputed', file=out)
        return target
    from cbha_inverse.fem.condensation import condense_segment
    from cbha_inverse.fem.geometry import geo_file_mesh
    mesh = geo_file_mesh(geometry, mesh_size=args.mesh_size, order=order)
    segment = condense_segment(mesh, args.youngs_modulus, args.poisson_ratio,
                               mesh_size=args.mesh_size, segment_length=args.segment_length,
                               density=args.density)
    write_segment(target, segment, name=geometry.stem, material=material, inputs_sha256=sha,
                  notes=[f'generated by condense_segment from {geometry.name}'])
    print(f'{target}: condensed P{order}, {segment.n_nodes} nodes in '
          f'{segment.timings["total"]:.2f} s', file=out)
    for warning in segment.warnings:
        print(f'{target}: warning: {warning}', file=out)
    return target


def segment_target(geometry, name, output=None, output_dir=None):
    """
    Return where the segment YAML of a geometry goes.

    Parameters
    ----------
    geometry : pathlib.Path
        The geometry file.
    name : str
        The segment name (``<name>.yaml``).
    output : path-like, optional
        Explicit segment YAML path.
    output_dir : path-like, optional
        Explicit directory.

    Returns
    -------
    pathlib.Path
        ``output``; else ``output_dir/<name>.yaml``; else ``<name>.yaml`` next to the geometry,
        or in the current directory when the geometry is one of the package's own data files
        (an install tree is overwritten by the next build, or read-only).

    Raises
    ------
    cbha_inverse.errors.ConfigError
        If the segment YAML would overwrite the geometry file.

    """
    if output is not None:
        target = Path(output)
    elif output_dir is not None:
        target = Path(output_dir) / f'{name}.yaml'
    elif geometry.resolve().is_relative_to(share_dir().resolve()):
        target = Path.cwd() / f'{name}.yaml'
    else:
        target = geometry.parent / f'{name}.yaml'
    if target.resolve() == geometry.resolve():
        raise ConfigError(geometry, 'name', f'the segment YAML {target} would overwrite the '
                          'geometry file: give --output')
    return target


def run(geometry, output=None, output_dir=None, order=None, mesh_size=None, force=False,
        out=None):
    """
    Condense one geometry YAML and write (or reuse) its segment YAML.

    Parameters
    ----------
    geometry : path-like
        Geometry YAML.
    output, output_dir : path-like, optional
        Where the segment YAML goes (see :func:`segment_target`).
    order : int, optional
        Element order override.
    mesh_size : float, optional  [m]
        Element size override.
    force : bool
        Recompute even when the cached file matches.
    out : file-like, optional
        Where progress is printed (default ``sys.stdout``).

    Returns
    -------
    pathlib.Path
        The segment YAML path.

    """
    from cbha_inverse.fem.segment_io import cached_segment, inputs_sha256, write_segment
    out = sys.stdout if out is None else out
    geometry = Path(geometry)
    spec = read_segment_spec(geometry)
    order = int(order or spec.mesh.order)
    mesh_size = float(mesh_size or spec.mesh.mesh_size)
    name = spec.name
    target = segment_target(geometry, name, output, output_dir)
    target.parent.mkdir(parents=True, exist_ok=True)
    sha = inputs_sha256(geometry, order, mesh_size)
    if not force and cached_segment(target, sha):
        print(f'{target}: cached (same inputs, sha256 {sha[:12]}), not recomputed', file=out)
        return target
    from cbha_inverse.fem.condensation import condense_segment
    segment = condense_segment(spec, order=order, mesh_size=mesh_size)
    notes = [f'generated by condense_segment from {geometry.name}']
    if segment.cavities:
        notes += pressure_notes(spec, segment, segment.cavities)
    write_segment(target, segment, name=name, material=spec.material.as_dict(),
                  inputs_sha256=sha, cavities=segment.cavities, notes=notes)
    print(f'{target}: condensed P{order}, mesh size {mesh_size:g} m, {segment.n_nodes} nodes, '
          f'{segment.n_elements} elements in {segment.timings["total"]:.2f} s', file=out)
    for note in notes[1:]:
        print(f'  {note}', file=out)
    for warning in segment.warnings:
        print(f'{target}: warning: {warning}', file=out)
    return target


def main(argv=None):
    """
    Run the ``condense_segment`` console script.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status: 0 on success, 2 on a bad input file or option (one line on stderr).

    """
    args = _parser().parse_args(argv)
    geometry = Path(args.geometry) if args.geometry else cbha_geometry_path()
    try:
        if geometry.suffix == '.geo':
            if not geometry.is_file():
                raise ConfigError(geometry, 'file', 'no such file')
            run_geo(args, geometry, segment_target(geometry, geometry.stem, args.output,
                                                   args.output_dir), sys.stdout)
        else:
            run(geometry, args.output, args.output_dir, args.order, args.mesh_size, args.force)
    except ConfigError as exc:
        return report_config_error(PROGRAM, exc)
    except (OSError, ValueError, np.linalg.LinAlgError) as exc:
        return report_config_error(PROGRAM, f'{geometry}: {exc}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
