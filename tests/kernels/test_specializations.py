"""The heaviest reach kernels compile once per process, whatever their callers pass.

A literal argument (``kappa = 2`` written in a kernel) or a sliced array (layout ``A`` instead of ``C``) makes numba
compile a function, and everything it calls, once more: on a fresh machine the error-floor chain was compiled five
times and the step twice (the demo's first run: 250 s, now 175 s; benchmarks/bench_first_run.py).  The floor and the tape interpreter now have explicit
signatures and the step's callers pass no literals; this checks that the specialisations stay single.  A callee
compiled into a caller that is loaded from the disk cache is not compiled at all (no signature in this process), so
the test bites when the kernels compile: on every fresh machine (the CI) and after every change to them.
"""

import reachconf as rc
from reachconf.models import vanderpol
from reachconf_kernels import adaptive, nonlinear, taylor


def test_reach_kernels_compile_once():
    X0 = rc.Interval([1.25, 2.35], [1.55, 2.45])
    tube = rc.reach(vanderpol(), X0, 1.0)  # adaptive: floors of order 2 and 3, on start sets and on slices
    assert tube.log is not None and {2, 3} <= set(tube.log.tensor_order.tolist())
    rc.reach(vanderpol(), X0, 0.2, options=rc.ReachOptions(algorithm="lin", tensor_order=3, time_step=0.01))
    rc.reach(vanderpol(), X0, 0.2, options=rc.ReachOptions(algorithm="lin", tensor_order=2, time_step=0.01))
    for fn in (adaptive.error_floor, adaptive.floor_rates, adaptive.floor_rate, taylor.evaluate,
               nonlinear.nonlinear_step, nonlinear._reduce_tol):  # fmt: skip  (reduce_adaptive: its tests call it)
        assert len(fn.signatures) <= 1, (fn.__name__, fn.signatures)
