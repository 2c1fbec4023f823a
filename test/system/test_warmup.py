"""The install-time warm-up compiles every kernel once, into numba's cache, and later loads it."""

import json
import os
import subprocess
import sys

from cbha_inverse.paths import config_path

# kernel modules of the benchmarks alone, which the warm-up leaves to them
BENCHMARK_ONLY = {'flop_rate'}

# Run in a child process: the warm-up, then, for every kernel module, what each of its compiled
# functions did in this process: its signatures (the copies compiled or loaded), its cache misses
# (compiled and written) and hits (loaded), and whether its cache index is on disk.
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
         'misses': len(value.stats.cache_misses), 'hits': len(value.stats.cache_hits),
         'index': value.signatures != [] and Path(value._cache._cache_file._index_path).exists()}
        for value in vars(module).values()
        if isinstance(value, Dispatcher) and value.py_func.__module__ == module.__name__]
print(json.dumps(report))
"""


# the variables with which coverage (``patch = subprocess``, setup.cfg) measures a child process
COVERAGE_CHILD = ('COVERAGE_PROCESS_START', 'COVERAGE_PROCESS_CONFIG')


def run_warmup(cache, measured=True):
    """
    Run the warm-up of a tendon scene and the CBHA over the numba cache ``cache``.

    With ``measured`` false the child process runs without coverage's line tracer (``make
    test``): the cold compile spends its time in numba's compiler, which the tracer slows by a
    third, and the Python code of the package it runs is the warm process's (measured) but for
    the lines of the kernel modules that run only while numba compiles (a record's boxing), which
    test/core/test_core_records.py runs too (it compiles functions of its own, measured).
    """
    env = {key: value for key, value in os.environ.items()
           if measured or key not in COVERAGE_CHILD}
    env['NUMBA_CACHE_DIR'] = str(cache)
    out = subprocess.run([sys.executable, '-c', PROBE], capture_output=True, text=True, env=env,
                         cwd=str(config_path().parents[0]), check=True, timeout=420)
    lines = out.stdout.strip().splitlines()
    assert lines[-3].startswith('warm-up: '), out.stdout
    assert lines[-3].endswith('(tendon_6f_8c, cbha)'), out.stdout
    assert lines[-2] == 'False', 'the warm-up must not import rclpy'
    return json.loads(lines[-1])


def test_the_warmup_compiles_every_kernel_once_into_the_cache_and_a_later_process_loads_it(
        tmp_path):
    """
    From an empty cache the warm-up compiles each kernel once; a second process compiles nothing.

    The tendon scene runs the cable kernels, the CBHA the cavities and the shape estimator on its
    string pots. The first process starts from an empty ``NUMBA_CACHE_DIR`` (a cold compile, as
    ``make install`` after a kernel changed): in every kernel module but the benchmarks' own
    (``BENCHMARK_ONLY``) some compiled function is compiled; each compiled function has exactly
    one signature (a caller passing a literal flag, a writable array where the others pass a
    read-only one, or another layout compiles a second copy of it and of everything it calls),
    was written to the cache and has its index on disk; the functions inlined into their callers
    (``inline='always'``) have none. The second process, over the same cache, loads every entry
    it calls and compiles nothing: a kernel without ``cache=True``, one numba cannot cache or one
    whose cache entry misses fails.
    """
    cold = run_warmup(tmp_path / 'numba-cache', measured=False)
    assert len(cold) >= 7
    for module, functions in cold.items():
        assert all(f['cached'] for f in functions), (module, functions)
        compiled = [f for f in functions if f['signatures'] > 0]
        if module in BENCHMARK_ONLY:
            assert not compiled, (module, compiled)
            continue
        if functions:
            assert compiled, f'the warm-up compiles nothing of the kernel module {module}'
        for f in compiled:
            assert (f['signatures'], f['misses'], f['hits']) == (1, 1, 0), (module, f)
            assert f['index'], (module, f)
    warm = run_warmup(tmp_path / 'numba-cache')
    entries = [(module, f) for module, functions in warm.items() for f in functions
               if f['signatures'] > 0]
    assert entries
    for module, f in entries:
        assert (f['signatures'], f['misses'], f['hits']) == (1, 0, 1), (module, f)
