"""The demo: lane changes of the closed-loop bicycle with a known disturbance box.

:func:`make_demo_suite` is the documented, seeded generator of the example
suite shipped in ``reachconf/data/demo`` (regenerate it with
``python -m reachconf.demo DIR``): a smooth lane change (3.5 m over 30 m) at
10 m/s, tracked by :func:`reachconf.models.vehicle_controller.tracking_law`; each
ODE gets a disturbance drawn uniformly from :data:`W_TRUE`, held for 0.1 s;
the states are measured with uniform noise in :data:`V_TRUE`; 50 Hz, 4 s.

:func:`run_demo` runs the main job on it: trace conformance with the true
sets, the W synthesis (steps 1–3 and the merge) and the X–Y reach tube with
the measured traces.
"""

from __future__ import annotations

import sys
import time
from importlib import resources
from pathlib import Path

import numpy as np

from reachconf.conformance.reachset import reachset_conformance
from reachconf.conformance.synthesis import synthesize_W
from reachconf.conformance.trace import trace_conformance
from reachconf.datasets.vehicle_campaign.maneuvers import lane_change
from reachconf.errors import OptionsError
from reachconf.io.atomic import atomic_write
from reachconf.io.cases import TestCase, TestSuite
from reachconf.io.files import save_suite
from reachconf.io.jsonfile import json_text
from reachconf.model.simulate import simulate
from reachconf.models import get_model
from reachconf.plot import save_figure
from reachconf.runfile import load_run
from reachconf.sets.core import Interval

__all__ = ["W_TRUE", "V_TRUE", "lane_change_reference", "weaving_reference", "make_demo_suite", "make_long_case",
           "run_demo", "demo_run_file"]

#: disturbance box used to generate the demo data (per ODE of the closed-loop bicycle)
W_TRUE = Interval([-0.05, -0.05, -0.01, -0.1, -0.1, -0.05], [0.05, 0.05, 0.01, 0.1, 0.1, 0.05])
#: measurement-noise box of the demo data (X, Y, psi, vx, vy, omega)
V_TRUE = Interval([-0.02, -0.02, -0.005, -0.03, -0.03, -0.01], [0.02, 0.02, 0.005, 0.03, 0.03, 0.01])


def lane_change_reference(t, v=10.0, width=3.5, start=5.0, length=30.0):
    """Reference ``(X_ref, Y_ref, psi_ref, v_ref, kappa_ref)`` of a smooth lane change, shape (K, 5).

    The lateral offset over the travelled distance ``s = v t`` is the
    campaign's :func:`~reachconf.datasets.vehicle_campaign.maneuvers.lane_change`
    (``Y(s) = width (u - sin(2 pi u) / (2 pi))``, ``u = (s - start) / length``
    clipped to [0, 1]): the curvature is continuous (no kink in the reference).
    """
    t = np.asarray(t, dtype=float)
    s = v * t
    Y, dY, ddY = lane_change(s, start, length, width)
    psi = np.arctan(dY)
    kappa = ddY / (1 + dY**2) ** 1.5
    return np.column_stack([s, Y, psi, np.full_like(t, v), kappa])


def weaving_reference(t, v=10.0, width=3.5, length=30.0, gap=20.0):
    """Reference of lane changes back and forth without end (for long recordings), shape (K, 5).

    Every ``2 (length + gap)`` metres: straight for ``gap``, a lane change to
    the left over ``length`` (the profile of :func:`lane_change_reference`),
    straight for ``gap``, back over ``length``.
    """
    t = np.asarray(t, dtype=float)
    s = v * t
    ph = np.mod(s, 2 * (length + gap))
    Y1, dY1, ddY1 = lane_change(ph, gap, length, width)
    Y2, dY2, ddY2 = lane_change(ph, 2 * gap + length, length, width)
    Y, dY, ddY = Y1 - Y2, dY1 - dY2, ddY1 - ddY2
    psi = np.arctan(dY)
    kappa = ddY / (1 + dY**2) ** 1.5
    return np.column_stack([s, Y, psi, np.full_like(t, v), kappa])


def make_long_case(samples: int, rate: float = 100.0, seed: int = 0, name: str | None = None,
                   maneuver: str = "weaving"):  # fmt: skip
    """A long recording of the closed-loop bicycle (the demo's model, W and V).

    ``samples`` samples at ``rate`` Hz; disturbances uniform in :data:`W_TRUE`
    held for 0.1 s, measurement noise uniform in :data:`V_TRUE`; deterministic
    for a given seed.  ``maneuver``: "weaving" (lane changes back and forth,
    :func:`weaving_reference`) or "straight" (lane keeping on a straight road:
    the controller tracks speed, not position, so the longitudinal position's
    uncertainty grows without bound, and only on a straight road does it stay
    out of the lateral loop — the setting in which a reach over hours stays
    bounded).  Used by the long-recording tests and benchmarks.
    """
    model = get_model("bicycle_closed_loop")
    rng = np.random.default_rng(seed)
    t = np.arange(int(samples)) / float(rate)
    if maneuver == "weaving":
        U = weaving_reference(t)
    elif maneuver == "straight":
        U = np.zeros((t.size, 5))
        U[:, 0] = 10.0 * t
        U[:, 3] = 10.0
    else:
        raise OptionsError(f"maneuver must be 'weaving' or 'straight', got {maneuver!r}")
    hold = max(1, int(round(0.1 * rate)))
    w = rng.uniform(W_TRUE.lo, W_TRUE.hi, size=(t.size // hold + 1, model.q)).repeat(hold, axis=0)[: t.size]
    X = simulate(model, np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]), t, inputs=U, disturbances=w, substeps=4)
    del w
    X += rng.uniform(V_TRUE.lo, V_TRUE.hi, size=X.shape)
    return TestCase(name or f"long_{samples}", "long", t, U, X, model.input_names, model.output_names)


def make_demo_suite(folder, n_cases: int = 3, seed: int = 2026, duration: float = 4.0, rate: float = 50.0):
    """Generate the demo suite (seeded, deterministic) into ``folder``; returns the TestSuite."""
    model = get_model("bicycle_closed_loop")
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, duration + 1e-9, 1.0 / rate), 10)
    cases = []
    hold = max(1, int(round(0.1 * rate)))
    for k in range(n_cases):
        U = lane_change_reference(t)
        w = rng.uniform(W_TRUE.lo, W_TRUE.hi, size=(t.size // hold + 1, model.q)).repeat(hold, axis=0)[: t.size]
        x0 = np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]) + rng.uniform(-1, 1, 6) * [0.05, 0.05, 0.005, 0.05, 0.02, 0.005]
        X = simulate(model, x0, t, inputs=U, disturbances=w, substeps=10)
        Y = X + rng.uniform(V_TRUE.lo, V_TRUE.hi, size=X.shape)
        cases.append(TestCase(f"lane_change_{k + 1:02d}", "lane_change", t, U, Y, model.input_names,
                              model.output_names))  # fmt: skip
    suite = TestSuite(cases, name="demo lane changes")
    save_suite(suite, folder, replace=True)
    return suite


def demo_run_file() -> Path:
    """Path of the shipped demo run file."""
    return Path(str(resources.files("reachconf") / "data" / "demo" / "run.toml"))


def run_demo(out, workers=None, log=print, scheduler=None) -> dict:
    """Run the demo into folder ``out``: returns the summary (also written to ``out/summary.json``).

    ``workers`` (local processes) or ``scheduler`` (a Dask address) run the
    synthesis on a pool, as in :func:`reachconf.conformance.synthesize_W`.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    spec = load_run(demo_run_file())
    suite = spec.suite()
    model = spec.model
    log(f"demo: {len(suite)} lane changes of the closed-loop bicycle, true W = {spec.W}")
    summary: dict = {"model": model.name, "cases": len(suite), "trace": {}, "timings": {}}

    t0 = time.perf_counter()
    for case in suite:
        res = trace_conformance(model, case, spec.W, spec.V, method=spec.trace_method, options=spec.trace_options)
        summary["trace"][case.name] = {"conformant": res.conformant, "margins": res.margins}
        verdict = "conformant" if res.conformant else f"not shown conformant ({res.message or 'no trace found'})"
        log(f"  trace conformance ({spec.trace_method}) of {case.name} with the true W, V: {verdict}")
    summary["timings"]["trace"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    synth = synthesize_W(model, suite, spec.V, spec.synthesis_options, workers=workers, scheduler=scheduler)
    summary["timings"]["synthesis"] = time.perf_counter() - t0
    summary["synthesis"] = synth.to_dict()
    synth.to_json(out / "synthesis.json")
    log("  minimal reachset-conformant W per maneuver (steps 1-3 + merge):")
    log("    " + synth.table().replace("\n", "\n    "))
    inside = {g: bool(np.all(W.lo >= spec.W.lo - 1e-9) and np.all(W.hi <= spec.W.hi + 1e-9)) for g, W in synth.groups.items()}
    summary["W_RC_inside_true_W"] = inside

    t0 = time.perf_counter()
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for i, case in enumerate(suite):
        W = synth.groups.get(case.group, spec.W)
        res = reachset_conformance(model, case, W, spec.V, options=spec.reach_options)
        res.plot(ax=ax, dims=("X", "Y"), color="C0", alpha=0.15, outline=False,
                 label="reach tube (W_RC)" if i == 0 else None)  # fmt: skip
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title("Closed-loop bicycle: X-Y reach tube with the synthesised W and the measured traces")
    ax.legend(loc="upper left")
    fig.tight_layout()
    png = save_figure(fig, out / "reach_tube_xy.png", dpi=120, bbox_inches=None)
    plt.close(fig)
    summary["timings"]["tube"] = time.perf_counter() - t0
    summary["timings"]["total"] = time.perf_counter() - t_all
    atomic_write(out / "summary.json", json_text(summary))
    log(f"demo done in {summary['timings']['total']:.1f} s: {png}, {out / 'synthesis.json'}, {out / 'summary.json'}")
    return summary


if __name__ == "__main__":  # regenerate the shipped data
    make_demo_suite(sys.argv[1] if len(sys.argv) > 1 else "demo_suite")
