"""
Regenerate the replay regression goldens (``make goldens``; ``--inputs``: the input bags too).

Run from the repository root with the package's venv: ``.venv/bin/python test/regen_goldens.py``.
It replays each input bag once (see ``test/replay.py``) and writes ``test/data/replay/
goldens.npz``; review the change (``git diff --stat``) before committing it.
"""

import argparse
from pathlib import Path
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from replay import GOLDENS, INPUTS, replay, TOLERANCE_PA, write_inputs  # noqa: E402, I100


def main(argv=None):
    """Regenerate; return 0."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--inputs', action='store_true', help='rewrite the input bags first')
    args = parser.parse_args(argv)
    if args.inputs:
        write_inputs()
        print(f'regenerated input bags: {", ".join(str(p) for p in INPUTS.values())}')
    goldens = {}
    with tempfile.TemporaryDirectory(prefix='cbha_goldens_') as workdir:
        for mode in INPUTS:
            goldens[mode] = replay(mode, Path(workdir) / mode)
            print(f'{mode} loop: {len(goldens[mode])} commands')
    np.savez(GOLDENS, tolerance_pa=TOLERANCE_PA, **goldens)
    print(f'regenerated goldens: {GOLDENS} (tolerance {TOLERANCE_PA:g} Pa)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
