"""Warm workers: a model is built here once and its compiled code goes to the pool's workers.

Before a run submits its first task, :func:`prepare_model` builds (or loads)
the model's compiled code in this process: local worker processes then only
load it from the shared cache folder instead of all generating it at once.  On
a Dask cluster the generated modules and numba's caches of the model and of
the kernels are installed on every worker (also on workers that join later)
by a worker plugin (:mod:`reachconf.runner.caches`), so a fresh worker loads
in seconds what it would otherwise build and compile for minutes.  Each worker
process then keeps the model it built (:mod:`reachconf.model.recipe`).

To prepare a cluster ahead of a run: ``reachconf warmup MODEL ... --scheduler
tcp://host:8786`` (or run ``reachconf warmup`` on each worker machine, or point
the workers' ``REACHCONF_CACHE`` at a shared folder).
"""

from __future__ import annotations

import importlib
import pkgutil
import time

from reachconf.runner.caches import (
    bundle_digest,
    install_cache_bundle,
    kernel_cache_bundle,
    model_cache_bundle,
)

__all__ = ["model_builds", "prepare_model", "ship_kernels", "load_kernels", "warm_model"]


def model_builds(reach_options=()) -> list:
    """The compiled builds ``(order, remainder)`` reaches with these options use (as :mod:`reachconf.reach` asks).

    The default build (``(2, "taylor")``, used by simulation and the trace
    checks) is always there; a ``"taylor"`` build serves every order.
    """
    builds = {(2, "taylor")}
    for ro in reach_options:
        if ro is None:
            continue
        remainder = getattr(ro, "remainder", "taylor")
        order = 3 if ro.effective_tensor_order == 3 and remainder != "taylor" else 2
        builds.add((order, remainder))
        if remainder != "taylor" and ro.tensor_order is None and ro.alg.name == "adaptive":
            builds.add((3, remainder))  # "adaptive" asks for tensor order 3 where order 2 does not fit
    return sorted(builds, key=lambda b: (b[0], str(b[1])))


def _build(model, order, remainder):
    return model.compiled(order=order, remainder=remainder)


def ship_kernels(pool) -> int:
    """Install this machine's compiled kernels on the Dask workers of ``pool``; returns the bytes sent (0: none)."""
    if pool.kind != "dask":
        return 0
    bundle = kernel_cache_bundle()
    if not bundle["numba"]:
        return 0
    pool.run_on_workers(f"reachconf-kernels-{bundle_digest(bundle)}", install_cache_bundle, bundle)
    return sum(len(e[3]) for e in bundle["numba"])


def prepare_model(pool, model, reach_options=()) -> list:
    """Build ``model`` here and make its compiled code available to the workers of ``pool``.

    Parameters
    ----------
    pool : reachconf.runner.Pool
    model : Model
    reach_options : sequence of ReachOptions or None
        The options the run's reaches use (their tensor orders decide the builds).

    Returns
    -------
    list of CompiledModel
        The builds (empty for a serial pool: the model is built when first used).
    """
    if not pool.parallel:
        return []
    comps = [_build(model, order, remainder) for order, remainder in model_builds(reach_options)]
    if pool.kind == "dask":
        ship_kernels(pool)
        bundle = model_cache_bundle(sorted({str(c.path) for c in comps}))
        pool.run_on_workers(f"reachconf-model-{model.structure_key}-{bundle_digest(bundle)}", install_cache_bundle,
                            bundle)  # fmt: skip
    return comps


def load_kernels() -> float:
    """Import every :mod:`reachconf_kernels` module (those with signatures compile or load now); returns seconds."""
    import reachconf_kernels

    t0 = time.perf_counter()
    for info in pkgutil.iter_modules(reachconf_kernels.__path__):
        importlib.import_module(f"reachconf_kernels.{info.name}")
    return time.perf_counter() - t0


def warm_model(model, builds=((2, "taylor"),)) -> dict:
    """Load (or build) the kernels and the model's builds in this process; what a warm worker has done.

    Runs on a worker (``reachconf warmup ... --scheduler``): the model
    arrives as its recipe and the process keeps it (see
    :mod:`reachconf.model.recipe`), so later jobs find it built.

    Returns
    -------
    dict
        ``kernels`` and ``model`` seconds, and ``from_cache`` (every build
        was found in the cache folder, none generated here).
    """
    kernels = load_kernels()
    t0 = time.perf_counter()
    comps = [_build(model, order, remainder) for order, remainder in builds]
    return {"kernels": kernels, "model": time.perf_counter() - t0, "from_cache": all(c.loaded_from_cache for c in comps)}
