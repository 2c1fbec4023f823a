"""
The compiled (numba) kernels: the only modules of the package that import numba.

Every equation the control tick, the static solver, the scenes' forward model and the plant
evaluate online has its one implementation here; ``cbha_inverse.warmup`` compiles them into
numba's on-disk cache (the Makefile finds them by the glob ``cbha_inverse/core/_kernels/*.py``).
"""

import importlib
import pkgutil


def kernel_modules():
    """
    Import and return every kernel module of this folder (the tests and the warm-up use it).

    Returns
    -------
    list of module

    """
    return [importlib.import_module(f'{__name__}.{info.name}')
            for info in pkgutil.iter_modules(__path__)]
