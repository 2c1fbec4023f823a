"""
Record the results of ``test/reference_cases.py`` into ``test/data/reference_results.npz``.

Run from the repository root with the package's venv: ``.venv/bin/python
test/record_reference_results.py``. The arrays in the repository were recorded on the code
before the compiled kernels were reorganised by equation (commit 72c4a64); record them again
only for a deliberate change of results, and review it.
"""

from pathlib import Path
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from reference_cases import all_cases, REFERENCE  # noqa: E402, I100


def main():
    """Run every case and write the arrays; return 0."""
    arrays = {}
    with tempfile.TemporaryDirectory() as folder:
        for case, results in all_cases(folder):
            for name, value in results.items():
                arrays[f'{case}/{name}'] = np.asarray(value)
            print(f'recorded {case}', flush=True)
    np.savez_compressed(REFERENCE, **arrays)
    print(f'wrote {len(arrays)} arrays to {REFERENCE}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
