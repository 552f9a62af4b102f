"""Prepare a machine or a Dask cluster for runs: build the models and compile the kernels once, ahead of time.

``reachconf warmup MODEL|RUN.toml ... [--scheduler tcp://host:8786]`` calls
:func:`warm_up`.  Here (the client machine) each model's builds are generated
and compiled into the cache folder and a short synthesis on a few samples
(the run file's first case, or a simulated one for a model name) compiles
every kernel a run uses.  With a scheduler, those files are installed on
every worker of the cluster (also on workers that join later, through a
worker plugin) and every worker process loads them, so the first case of a
run on a fresh worker starts at once instead of after minutes of compiling.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from reachconf.conformance.synthesis import SynthesisOptions, synthesize_W
from reachconf.io.cases import TestCase, TestSuite
from reachconf.model.shipping import load_kernels, model_builds, prepare_model, warm_model
from reachconf.model.simulate import simulate
from reachconf.reach_options import ReachOptions
from reachconf.runfile import load_run, resolve_model
from reachconf.runner.pool import use_pool
from reachconf.sets.core import Interval

__all__ = ["warm_up", "warm_up_target"]

#: samples of the short synthesis that compiles the kernels
SAMPLES = 11


def _synthetic_case(model) -> TestCase:
    """A few samples simulated from x = 1 with zero inputs and disturbances (only to compile the kernels)."""
    t = np.linspace(0.0, 0.1, SAMPLES)
    X = simulate(model, np.ones(model.n), t, inputs=np.zeros((t.size, model.m)),
                 disturbances=np.zeros((t.size, model.q)), substeps=2, check=False)  # fmt: skip
    Y = np.array([model.h(x, np.zeros(model.m)) for x in X])
    if not np.all(np.isfinite(Y)):
        Y = np.zeros_like(Y)
    return TestCase("warmup", "warmup", t, np.zeros((t.size, model.m)), Y, model.input_names, model.output_names)


def warm_up_target(target, orders=(2, 3)):
    """A model and what a run of it needs, from a run file (``.toml``) or a model name.

    Returns ``(model, reach_options, suite, V, synthesis_options)``: a run
    file gives its own; a model name all ``orders`` and ``suite=None`` (one
    simulated case is made once the model is built, see :func:`warm_up`).
    """
    if str(target).endswith(".toml"):
        spec = load_run(target)
        full = next(iter(spec.suite()))
        X0 = (spec.initial_sets(TestSuite([full])) or {}).get(full.name)  # [sets] X0 / unmeasured; None: eq. 67
        options = dataclasses.replace(spec.synthesis_options, X0=X0)
        reach = (spec.reach_options, options.reach, options.reach_fallback)
        case = full.segment(full.t[0], full.t[min(SAMPLES, full.t.size) - 1])
        V = spec.V if spec.V is not None else Interval(-np.ones(spec.model.p), np.ones(spec.model.p))
        return spec.model, reach, TestSuite([case]), V, options
    model = resolve_model(str(target), where=f"warmup {target}")
    reach = tuple(ReachOptions(tensor_order=o) for o in orders)
    options = SynthesisOptions(reach=reach[0], reach_fallback=reach[-1] if len(reach) > 1 else None)
    return model, reach, None, Interval(-np.ones(model.p), np.ones(model.p)), options


def warm_up(targets, scheduler=None, orders=(2, 3), pool=None, log=print) -> dict:
    """Build and compile what runs of ``targets`` need, here and on the workers of a Dask cluster.

    Parameters
    ----------
    targets : sequence of str
        Model names (built-in or ``module:attribute``) or run files.
    scheduler : str or dask.distributed.Client, optional
        The cluster whose workers get the compiled files and load them.
    orders : sequence of {2, 3}
        Tensor orders to build for model names (run files use their options).
    pool : reachconf.runner.Pool, optional
        The run's pool instead of ``scheduler``.
    log : callable
        Receives one line per step.

    Returns
    -------
    dict
        ``{"here": {model: {...seconds...}}, "workers": {worker: {model: {...}}}}``.
    """
    report = {"here": {}, "workers": {}}
    resolved = [warm_up_target(target, orders) for target in targets]  # every name and file checked first
    t0 = time.perf_counter()
    seconds = load_kernels()
    log(f"kernels: loaded in {seconds:.1f} s")
    prepared = []
    for model, reach, suite, V, options in resolved:
        t1 = time.perf_counter()
        builds = model_builds(reach)
        comps = [model.compiled(order=o, remainder=r) for o, r in builds]
        built = time.perf_counter() - t1
        suite = suite if suite is not None else TestSuite([_synthetic_case(model)])
        t1 = time.perf_counter()
        quick = dataclasses.replace(options, alpha_iterations=1, merge_iterations=1, step2_decimate=1)
        try:  # compiles every kernel a synthesis calls; the numbers do not matter
            synthesize_W(model, suite, V, quick, progress=False)
            note = ""
        except Exception as exc:  # noqa: BLE001 - what compiled before the stop stays compiled; say why it stopped
            note = f" (the short synthesis stopped early: {type(exc).__name__}: {' '.join(str(exc).split())[:100]})"
        how = "loaded from the cache" if all(c.loaded_from_cache for c in comps) else "generated and compiled"
        log(f"{model.name}: builds {[o for o, _ in builds]} {how} in {built:.1f} s; kernels of a synthesis ready in "
            f"{time.perf_counter() - t1:.1f} s{note}")  # fmt: skip
        report["here"][model.name] = {"build_seconds": built, "from_cache": how.startswith("loaded"),
                                      "synthesis_seconds": time.perf_counter() - t1}  # fmt: skip
        prepared.append((model, reach, builds))
    if scheduler is None and pool is None:
        log(f"this machine is ready ({time.perf_counter() - t0:.1f} s)")
        return report
    with use_pool(pool, None, scheduler) as p:
        for model, reach, builds in prepared:
            prepare_model(p, model, reach)
            for worker, r in sorted(p.on_each_worker(warm_model, model, builds).items()):
                report["workers"].setdefault(worker, {})[model.name] = r
                log(f"{worker}: {model.name} ready in {r['kernels'] + r['model']:.1f} s "
                    f"({'from the installed cache' if r['from_cache'] else 'built there'})")  # fmt: skip
        log(f"{p.describe()}: {len(report['workers'])} worker(s) ready ({time.perf_counter() - t0:.1f} s)")
    return report
