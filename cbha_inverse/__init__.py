"""
Quasi-static FEM modelling and inverse control of continuum robots with rigid vertebrae.

The package implements Bosman et al., ICRA 2015 for Festo's Compact Bionic Handling Assistant:
``core`` (mechanics, BTD solver, inverse QP), ``fem`` (offline condensation), ``ros`` (nodes).
"""

import os

__version__ = '0.1.0'

# The control tick is made of small dense factorizations: OpenBLAS worker threads make them up to
# ~50x slower on a loaded 2-core machine (dpotrs 96x96, 20 RHS: 30 ms threaded vs 20 us single).
# Pin one BLAS thread unless the user chose otherwise; it only takes effect when cbha_inverse is
# imported before numpy, which is the case for every node and command of the package.
for _variable in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS'):
    os.environ.setdefault(_variable, '1')
