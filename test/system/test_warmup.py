"""The install-time warm-up fills numba's cache for every kernel module of the tick."""

import os
import subprocess
import sys

from cbha_inverse.core._kernels import kernel_modules
from cbha_inverse.paths import config_path


def test_warmup_writes_the_numba_cache_of_every_kernel_module(tmp_path):
    """
    A cold warm-up into an empty ``NUMBA_CACHE_DIR`` of a tendon scene and the CBHA.

    The tendon scene compiles the cable kernels, the CBHA the cavities and the shape estimator
    on its string pots: ~20-60 s of compiling.
    """
    cache = tmp_path / 'numba'
    env = {**os.environ, 'NUMBA_CACHE_DIR': str(cache)}
    code = ('import sys; from cbha_inverse.warmup import main; '
            "main(['--scenes', 'tendon_6f_8c', 'cbha']); "
            "print('rclpy' in sys.modules)")
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, env=env,
                         cwd=str(config_path().parents[0]), check=True, timeout=240)
    lines = out.stdout.strip().splitlines()
    assert lines[-2].startswith('warm-up: '), out.stdout
    assert lines[-2].endswith('(tendon_6f_8c, cbha)'), out.stdout
    assert lines[-1] == 'False', 'the warm-up must not import rclpy'
    indexed = {path.name.split('.')[0] for path in cache.rglob('*.nbi')}
    kernels = {module.__name__.rsplit('.', 1)[1] for module in kernel_modules()}
    assert len(kernels) >= 7 and kernels <= indexed, (sorted(kernels), sorted(indexed))
