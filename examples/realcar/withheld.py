"""Known effects injected into the recorded real-car signals (withheld-effect checks of the diagnosis).

The recording is the truth of what the car did.  Each injection changes what
the *model* is given so that the true system has an effect the model lacks:

=================  ===================================================================  ==========================
name               injected into the recorded signals                                     the diagnosis should name
=================  ===================================================================  ==========================
``dead_time``      ``delta_rec(t) = delta(t + T)``: the real angle is the record delayed   ``dead_time(delta)`` T
``lag``            ``delta_rec`` = the request of a first-order lag whose output is the   ``actuator_lag(delta)`` tau
                   recorded angle (exact inverse of the library's lag filter)
``steer_offset``   ``delta_rec = delta - c``: the real angle is ``delta_rec + c``          ``input_offset(delta)`` c
``yaw_bias``       ``omega_rec = omega + b`` (sensor bias)                                 ``output_offset(omega)`` b
``ax_scale``       ``ax_rec = ax / k``: the real acceleration is ``k ax_rec``              ``input_scale(ax)`` k
=================  ===================================================================  ==========================

:func:`inject` works on the columns of :func:`data.read_run` before the run
is cut into cases, so the injected effect is continuous across cases.
:func:`judge` checks a diagnosis of an injected run against the truth, sized
relative to the clean run's own fit of the same effect (the real car has
biases and delays of its own).  As a command, the clean run and every
injection are diagnosed and judged::

    python examples/realcar/withheld.py --data ../shared/data/realcar --out DIR [--loss-scale sensor]
        [--only yaw_bias ax_scale] [--value yaw_bias=0.02] [--stop 120] [--signal-only] [--stage2]
        [--no-reference] [--reference-loss difference]

writes ``DIR/withheld.json`` and ``DIR/withheld.md``.  With ``--stage2`` (the
two-stage workflow of ``adopt.py``), the clean run's findings are adopted into
the model (fitted on the clean run, the car's own steering timing included)
and the clean run and every injection are diagnosed again with that model,
its parameters fixed, and the signal candidates; the injections are judged
against the clean run's stage-2 fit, and the adoption is recorded.  By default (``--reference``; since 26 Nov)
every injection is diagnosed against the clean run as the reference (``rc.diagnose(..., reference=clean_suite)``: which effect
explains how the injected run differs from the clean run, :mod:`reachconf.diagnose.reference`; ``--reference-loss``
chooses how the two are compared, by default the difference of the residuals); ``--no-reference`` diagnoses each
injected run alone (single stage), as before; ``--stage2`` implies it unless ``--reference`` is given.
"""

from __future__ import annotations

import argparse
import sys
import time
import os
from pathlib import Path

import numpy as np

if str(Path(__file__).resolve().parent) not in sys.path:  # data.py next to this file
    sys.path.insert(0, str(Path(__file__).resolve().parent))

#: name -> (effect, target, parameter) the diagnosis should report
INJECTIONS = {"dead_time": ("dead_time", "delta", "T"), "lag": ("actuator_lag", "delta", "tau"),
              "steer_offset": ("input_offset", "delta", "c"), "yaw_bias": ("output_offset", "omega", "c"),
              "ax_scale": ("input_scale", "ax", "k")}  # fmt: skip
#: the injected values of the command (the tests use others)
VALUES = {"dead_time": 0.06, "lag": 0.08, "steer_offset": 0.012, "yaw_bias": 0.025, "ax_scale": 0.85}
#: scale effects are judged multiplicatively (k_injected vs k_found / k_clean), the others additively
SCALES = ("input_scale",)
#: the effects that act on the recorded signals only (no tyre candidates: no model code to generate)
SIGNAL_CANDIDATES = (("dead_time", "delta"), ("actuator_lag", "delta"), ("input_offset", "delta"),
                     ("input_scale", "ax"), ("output_offset", "omega"), ("output_offset", "vy"))  # fmt: skip


def lag_request(t, y, tau):
    """The zero-order-hold request ``u`` whose first-order lag (interval means, as
    :func:`reachconf_kernels.signals.first_order_lag` computes them) is ``y``."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    u = np.empty_like(y)
    state = y[0]
    u[0] = y[0]
    for k in range(y.size - 1):
        r = (t[k + 1] - t[k]) / tau
        g = -np.expm1(-r) / r  # interval mean weight of the state
        u[k] = (y[k] - g * state) / (1.0 - g) if k > 0 else y[0]
        state = u[k] + (state - u[k]) * np.exp(-r)
    u[-1] = u[-2]
    return u


def inject(cols, name, value):
    """The recorded columns with the effect ``name`` of size ``value`` injected; and the truth.

    Returns ``(cols, truth)`` with ``truth = {"effect", "target", "params"}``.
    """
    if name not in INJECTIONS:
        raise ValueError(f"unknown injection {name!r}; known: {sorted(INJECTIONS)}")
    from data import repair_glitches

    out = {k: np.array(v, float) for k, v in cols.items()}
    t = out["t"]
    # the truth is the repaired recording: a lag's inverse would blow the four one-sample glitches of the
    # steering record up into multi-sample spikes that the suite's glitch repair no longer recognises
    out["delta"], _ = repair_glitches(cols["delta"])
    cols = {**cols, "delta": out["delta"]}
    if name == "dead_time":
        out["delta"] = np.interp(t + value, t, cols["delta"])
    elif name == "lag":
        out["delta"] = lag_request(t, cols["delta"], value)
    elif name == "steer_offset":
        out["delta"] = cols["delta"] - value
    elif name == "yaw_bias":
        out["omega"] = cols["omega"] + value
    elif name == "ax_scale":
        out["ax"] = cols["ax"] / value
    effect, target, param = INJECTIONS[name]
    return out, {"effect": effect, "target": target, "params": {param: float(value)}}


def clean_value(clean, effect, target, param):
    """The clean run's own fit of ``effect(target)`` alone (held-out folds' mean, else its screening fit)."""
    label = f"{effect}({target})"
    for e in clean.ranked_effects:
        if e.get("label") == label and param in e.get("params", {}):
            return float(e["params"][param])
    raise KeyError(f"the clean diagnosis has no fit of {label}")


def judge(report, clean, truth, tolerance=0.3) -> dict:
    """Is the injected effect named first and sized within ``tolerance`` relative to the clean run?

    First: the first named effect that the clean run's diagnosis does not name (the car's own effects, such as
    its tyre saturation, are named in both).

    Size: how far the named parameter moved from the clean run's fit of the
    same effect (``found - clean``), against the injected value; for a scale,
    ``found / clean - 1`` against ``k - 1``.
    """
    eff, tgt = truth["effect"], truth["target"]
    (param, size), = truth["params"].items()
    named = [(e["effect"], e["target"]) for e in report.named]
    # first among what the clean run does not name (the car's own effects, e.g. its tyre saturation, stay named)
    own = {(e["effect"], e["target"]) for e in clean.named}
    new = [n for n in named if n not in own]
    first = bool(new) and new[0] == (eff, tgt)
    # an "indistinguishable" verdict that lists the injected effect among the explanations it cannot separate
    alts = [{tuple(p) for p in a.get("parts", [])} for a in report.decision.get("alternatives", [])]
    among = report.decision.get("status") == "indistinguishable" and any((eff, tgt) in a for a in alts + [set(named)])
    ref = clean_value(clean, eff, tgt, param)
    entry = next((e for e in report.named if (e["effect"], e["target"]) == (eff, tgt)), None)
    found = float(entry["params"][param]) if entry else clean_value(report, eff, tgt, param)
    multiplicative = eff in SCALES
    moved = found / ref - 1 if multiplicative else found - ref
    want = size - 1 if multiplicative else size
    error = (moved - want) / abs(want)
    scored = [e for e in report.ranked_effects if e.get("held_out_loss") is not None]
    rank, best = next(((i + 1, e) for i, e in enumerate(scored) if (eff, tgt) in {tuple(p) for p in e.get("parts", [])}),
                      (None, {}))  # fmt: skip
    return {"truth": f"{eff}({tgt}) {param} = {size:g}", "status": report.decision.get("status"),
            "named": " + ".join(f"{e}({t})" for e, t in named) or "none", "named_first": first,
            "indistinguishable": bool(among) and not first,
            "from_named_model": entry is not None, "found": found, "clean": ref, "moved": moved, "injected": want,
            "relative_error": error, "sized": first and abs(error) <= tolerance, "best_rank": rank,
            "best_model": best.get("label"), "best_gain": best.get("prediction_gain"), "best_z": best.get("z_vs_base"),
            "verdict": report.verdict}  # fmt: skip


def default_data() -> Path:
    """``$REACHCONF_DATA/realcar``, else ``../shared/data/realcar`` from the repo root (until 3 Dec the default
    pointed one folder too high, at ``/shared/data/realcar``)."""
    root = os.environ.get("REACHCONF_DATA")
    return (Path(root) if root else Path(__file__).resolve().parents[2].parent / "shared" / "data") / "realcar"


def main(argv=None):
    from data import make_suite, noise_V, read_run
    from diagnosis import CANDIDATES, FIT, run_diagnosis

    import reachconf as rc
    from reachconf.io import atomic_write, json_text
    from reachconf.models import single_track

    ap = argparse.ArgumentParser(description="withheld effects injected into the real car's recording")
    ap.add_argument("--data", default=str(default_data()),
                    help="data folder (default: ../shared/data/realcar from the repo root, or $REACHCONF_DATA)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--only", nargs="*", choices=sorted(INJECTIONS), default=list(INJECTIONS))
    ap.add_argument("--value", action="append", default=[], help="NAME=VALUE: another injected value")
    ap.add_argument("--loss-scale", default=None, choices=("sensor", "residual", "case"),
                    help="DiagnoseOptions.loss_scale (default: the library's default)")
    ap.add_argument("--reference-loss", default=None, choices=("excess", "difference"),
                    help="DiagnoseOptions.reference_loss (with --reference; default: the library's default)")
    ap.add_argument("--start-state", default=None, choices=("auto", "past", "prefix", "centered"),
                    help="DiagnoseOptions.start_state (default: the library's default)")
    ap.add_argument("--stop", type=float, default=None, help="only the first STOP seconds of the run")
    ap.add_argument("--signal-only", action="store_true", help="signal candidates only (no tyre models)")
    ap.add_argument("--stage2", action="store_true",
                    help="adopt the clean run's findings into the model, then diagnose with it (adopt.py)")
    ap.add_argument("--reference", action=argparse.BooleanOptionalAction, default=None,
                    help="diagnose every injection against the clean run as the reference (what changed; the "
                         "default without --stage2); --no-reference: each injected run alone")
    args = ap.parse_args(argv)
    if args.reference is None:  # against the clean run, except in the two-stage workflow (measured without it)
        args.reference = not args.stage2
    values = dict(VALUES)
    for item in args.value:
        k, v = item.split("=")
        values[k] = float(v)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cols = read_run(args.data)
    stop = None if args.stop is None else cols["t"][0] + args.stop
    half = np.array([h for _, h in noise_V(cols).values()])
    V = rc.Interval(-half, half)
    opts = rc.DiagnoseOptions(**({"loss_scale": args.loss_scale} if args.loss_scale else {}),
                              **({"reference_loss": args.reference_loss} if args.reference_loss else {}),
                              **({"start_state": args.start_state} if args.start_state else {}))
    effects = SIGNAL_CANDIDATES if args.signal_only else CANDIDATES

    def diag(c, reference=None):
        w, cpu = time.perf_counter(), time.process_time()
        rep = run_diagnosis(single_track(), make_suite(c, stop=stop), V, effects=effects, options=opts,
                            reference=reference)  # fmt: skip
        return rep, time.perf_counter() - w, time.process_time() - cpu

    clean, w, cpu = diag(cols)
    clean.to_json(out / "clean.json")
    rows = {"clean": {"verdict": clean.verdict, "wall": w, "cpu": cpu, "loss_scale": clean.base.get("loss_scale")}}
    print(f"clean ({w:.0f} s wall, {cpu:.0f} s CPU): {clean.verdict}", flush=True)
    adopted = None
    if args.stage2:
        from adopt import adopt

        w, cpu = time.perf_counter(), time.process_time()
        clip = (lambda c: {k: v[cols["t"] <= stop] for k, v in c.items()}) if stop is not None else (lambda c: c)
        adopted = adopt(single_track(), clip(cols), clean, FIT, options=opts)
        print(f"adopted ({time.perf_counter() - w:.0f} s wall): {adopted.to_dict()}", flush=True)

        def diag(c, reference=None):  # stage 2: the adopted model, its parameters fixed, the signal candidates
            w, cpu = time.perf_counter(), time.process_time()
            ref = make_suite(adopted.apply(reference), stop=stop) if reference is not None else None
            rep = run_diagnosis(adopted.model, make_suite(adopted.apply(c), stop=stop), V, effects=SIGNAL_CANDIDATES,
                                options=opts, fit_params=(), reference=ref)  # fmt: skip
            return rep, time.perf_counter() - w, time.process_time() - cpu

        clean, w, cpu = diag(cols)
        clean.to_json(out / "clean_stage2.json")
        rows["clean_stage2"] = {"verdict": clean.verdict, "wall": w, "cpu": cpu, "adopted": adopted.to_dict()}
        print(f"clean, stage 2 ({w:.0f} s wall, {cpu:.0f} s CPU): {clean.verdict}", flush=True)
    for name in args.only:
        inj, truth = inject(cols, name, values[name])
        rep, w, cpu = diag(inj, reference=(cols if args.stage2 else make_suite(cols, stop=stop)) if args.reference
                           else None)  # fmt: skip
        rep.to_json(out / f"{name}.json")
        rows[name] = {**judge(rep, clean, truth), "wall": w, "cpu": cpu}
        r = rows[name]
        print(f"{name}: named {r['named']} (first: {r['named_first']}, indistinguishable: {r['indistinguishable']}), "
              f"moved {r['moved']:.4g} vs {r['injected']:.4g} "
              f"({100 * r['relative_error']:+.0f} %), best rank {r['best_rank']} {r['best_model']} gain {r['best_gain']} "
              f"z {r['best_z']} ({w:.0f} s wall, {cpu:.0f} s CPU)",
              flush=True)  # fmt: skip
    result = {"loss_scale": opts.loss_scale, "min_improvement": opts.min_improvement, "stop": args.stop, "signal_only": args.signal_only, "values": values,
              "stage2": args.stage2, "reference": args.reference, "adopted": adopted.to_dict() if adopted else None, "rows": rows}  # fmt: skip
    atomic_write(out / "withheld.json", json_text(result))
    lines = [f"# Injected effects (loss_scale = {opts.loss_scale}, min_improvement = {opts.min_improvement:g}"
             f"{', two-stage' if adopted else ''}{', against the clean run' if args.reference else ''})", ""]  # fmt: skip
    if adopted:
        a = adopted.to_dict()
        found = [f"{k}: " + ", ".join(f"{p} = {v:.4g}" for p, v in pv.items()) for k, pv in a["effect_params"].items()]
        lines += ["Adopted from the clean run: " + "; ".join(found or ["no effect"])
                  + "; " + ", ".join(f"{k} = {v:.4g}" for k, v in a["params"].items())
                  + f"; steering timing {a['timing']:+.4f} s", ""]  # fmt: skip
    lines += ["| injected | named | first | moved / injected | error | best rank | its held-out gain (z) |",
              "|---|---|---|---|---|---|---|"]  # fmt: skip
    # (first: True, False, or "indistinguishable" when the verdict lists it among explanations it cannot separate)
    for name in args.only:
        r = rows[name]
        gain = "" if r["best_gain"] is None else f"{100 * r['best_gain']:.0f} % ({r['best_z']:.1f}): {r['best_model']}"
        first = "indistinguishable" if r.get("indistinguishable") else r["named_first"]
        lines.append(f"| {r['truth']} | {r['named']} | {first} | {r['moved']:.4g} / {r['injected']:.4g} "
                     f"| {100 * r['relative_error']:+.0f} % | {r['best_rank']} | {gain} |")  # fmt: skip
    atomic_write(out / "withheld.md", "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
