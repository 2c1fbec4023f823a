"""The install-time warm-up fills numba's cache for every kernel module the scenes use."""

import json
import subprocess
import sys

from cbha_inverse.paths import config_path

# kernel modules of the benchmarks alone, which the warm-up leaves to them
BENCHMARK_ONLY = {'flop_rate'}

# Run in a child process: the warm-up, then, for every kernel module, what its compiled functions
# did in this process (signatures) and through numba's cache (hits: loaded, misses: compiled and
# written), and whether their cache index is on disk.
PROBE = """
import json, sys
from pathlib import Path
from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher
from cbha_inverse.core._kernels import kernel_modules
from cbha_inverse.warmup import main
main(['--scenes', 'tendon_6f_8c', 'cbha'])
print('rclpy' in sys.modules)
report = {}
for module in kernel_modules():
    name = module.__name__.rsplit('.', 1)[1]
    report[name] = [
        {'function': value.py_func.__name__, 'signatures': len(value.signatures),
         'cached': isinstance(value._cache, FunctionCache),
         'through_cache': set(value.signatures)
         <= set(value.stats.cache_hits) | set(value.stats.cache_misses),
         'index': value.signatures != [] and Path(value._cache._cache_file._index_path).exists()}
        for value in vars(module).values()
        if isinstance(value, Dispatcher) and value.py_func.__module__ == module.__name__]
print(json.dumps(report))
"""


def test_warmup_writes_the_numba_cache_of_every_kernel_module():
    """
    The warm-up of a tendon scene and the CBHA reaches every kernel module through numba's cache.

    The tendon scene runs the cable kernels, the CBHA the cavities and the shape estimator on its
    string pots. In every kernel module (but the benchmarks' own, ``BENCHMARK_ONLY``, reached by
    none) at least one compiled function gets a signature in the
    warm-up's process, each such signature was loaded from numba's on-disk cache or compiled and
    written to it (``make install`` ran the warm-up, so this costs seconds, not the minute of a
    cold compile), and its cache index is on disk: a kernel module the warm-up does not reach, a
    kernel without ``cache=True`` or one numba cannot cache fails.
    """
    out = subprocess.run([sys.executable, '-c', PROBE], capture_output=True, text=True,
                         cwd=str(config_path().parents[0]), check=True, timeout=240)
    lines = out.stdout.strip().splitlines()
    assert lines[-3].startswith('warm-up: '), out.stdout
    assert lines[-3].endswith('(tendon_6f_8c, cbha)'), out.stdout
    assert lines[-2] == 'False', 'the warm-up must not import rclpy'
    report = json.loads(lines[-1])
    assert len(report) >= 7
    for module, functions in report.items():
        assert all(f['cached'] for f in functions), (module, functions)
        used = [f for f in functions if f['signatures'] > 0]
        if module in BENCHMARK_ONLY:
            assert not used, (module, used)
            continue
        assert used, f'the warm-up compiles nothing of the kernel module {module}'
        assert all(f['through_cache'] and f['index'] for f in used), (module, used)
