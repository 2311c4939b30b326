"""Speed benchmarks: the asv suite (``asv_*`` modules, ``asv run --python=same``), the FEM
reference timings (``bench_fem``) and the performance study (``run``).

asv imports this package from the checkout; the checkout's own ``hybmss`` and
``fem_reference`` come first on the path, so the suite measures the code beside it rather than
whatever copy the environment has installed.
"""

import os
import sys

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if _ROOT not in sys.path[:1]:
    sys.path.insert(0, _ROOT)
