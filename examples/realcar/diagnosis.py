"""The gap diagnosis on the real run: ``rc.diagnose(single_track(), suite)`` with the Fiala tyre in the library.

Used by ``run.py`` (step 5) and by the withheld-effect checks (``withheld.py``).
"""

from __future__ import annotations

import numpy as np

import reachconf as rc
from reachconf.diagnose import EFFECTS
from reachconf.io import atomic_write

#: the candidates: the tyre effect on the front axle and on both, and the steering / sensor effects a car can
#: have.  Not ``tire_fiala(c_r)``: a saturating rear axle alone makes this understeering car's model spin, its
#: fit diverged on every run measured (screening cost 400-1500 times the others', never among the scored), and
#: its code generation cost ~30 s CPU on a fresh cache
CANDIDATES = (("tire_fiala", "c_f"), ("tire_fiala", "axles"), ("dead_time", "delta"),
              ("actuator_lag", "delta"), ("input_offset", "delta"), ("input_scale", "ax"),
              ("output_offset", "omega"), ("output_offset", "vy"))  # fmt: skip
#: base parameters re-identified jointly with every candidate (mass and CG position are measured; the yaw
#: inertia and the cornering stiffnesses are the README's estimates)
FIT = ("J_z", "c_f", "c_r")


def run_diagnosis(model, suite, V, seed=0, progress=False, effects=CANDIDATES, options=None, fit_params=FIT,
                  reference=None):  # fmt: skip
    """The :class:`reachconf.diagnose.GapReport` of ``model`` on ``suite`` with :data:`CANDIDATES`.

    ``options``: a :class:`reachconf.diagnose.DiagnoseOptions` (default: the library's defaults);
    ``fit_params``: the base parameters refitted with every candidate (default :data:`FIT`);
    ``reference``: the same cases without the change (``rc.diagnose(..., reference=)``).
    """
    return rc.diagnose(model, suite, effects=list(effects), fit_params=fit_params, V=V, seed=seed, progress=progress,
                       options=options, reference=reference)  # fmt: skip


def named_model(model, report):
    """The refitted base model with the named effects (or, if none is named, the best scored model's effects).

    Returns ``(model, parts, named, signal)``: the model with the named
    model-kind effects (the tyre) applied, the ``(effect, target, params)``
    of every named effect, whether the report named them, and the
    input/output effects as ``(Effect, target, theta)`` for
    :func:`as_seen_by_model` — applied to the signals, as the diagnosis
    does, so that the model keeps the compiled code the diagnosis cached
    (a model with an input scale substituted into its equations would need
    its own code generation: a minute of sympy for the tyre's derivatives).
    """
    fitted = model.with_params(**{k: v for k, v in report.base.get("params", {}).items() if k in model.param_names})
    parts = [(e["effect"], e["target"], e["params"]) for e in report.named]
    named = bool(parts)
    if not parts:
        best = next((e for e in report.ranked_effects if e.get("held_out_loss") is not None), None)
        if best is None:
            return fitted, [], False, []
        parts = [(eff, tgt, best["params_by_effect"][f"{eff}({tgt})"]) for eff, tgt in best["parts"]]
    signal = []
    for eff_name, tgt, params in parts:
        eff = EFFECTS[eff_name]
        theta = [params[p] for p in eff.params]
        if eff.kind in ("input", "output"):
            signal.append((eff, tgt, tuple(theta)))
        else:
            fitted = eff.apply_model(fitted, tgt, theta)
    return fitted, parts, named, signal


def as_seen_by_model(model, suite, signal):
    """The suite's cases with the input/output effects ``signal`` of :func:`named_model` applied."""
    from reachconf.diagnose.fit import Candidate, transformed_case
    from reachconf.io import TestSuite

    if not signal:
        return suite
    cand = Candidate(tuple((e, t) for e, t, _ in signal))
    theta = {(e.name, t): th for e, t, th in signal}
    return TestSuite([transformed_case(model, c, cand, theta) for c in suite], name=suite.name)


def diagnosis_markdown(report, bands_before=None, bands_after=None, label="with the effect") -> str:
    """The diagnosis section of realcar.md: verdict, named effects, ranking, W per channel and per |ay| band."""
    lines = ["## Gap diagnosis: rc.diagnose(single_track(), suite)", "", f"**Verdict:** {report.verdict}", ""]
    for e in report.named:
        lines.append(f"- named: {e['effect']}({e['target']}) " + ", ".join(
            f"{p} = {v:.4g} ± {e['params_std'][p]:.2g}" for p, v in e["params"].items()))  # fmt: skip
    lines += ["", "| rank | model | parameters (mean over folds) | held-out prediction gain | z vs base |",
              "|---|---|---|---|---|"]  # fmt: skip
    scored = [e for e in report.ranked_effects if e.get("held_out_loss") is not None]
    for i, e in enumerate(scored):
        ps = "; ".join(f"{lab}: " + ", ".join(f"{k} = {v:.4g}" for k, v in pv.items())
                       for lab, pv in e.get("params_by_effect", {}).items())  # fmt: skip
        lines.append(f"| {i + 1} | {e['label']} | {ps} | {100 * e['prediction_gain']:.0f} % | {e['z_vs_base']:.1f} |")
    base = report.base
    lines += ["", "Refitted base parameters: " + ", ".join(f"{k} = {v:.4g}" for k, v in base.get("params", {}).items())]
    ba = report.before_after.get("W")
    if ba:
        lines += ["", "W per channel on the held-out cases' 2-s segments (smallest zero-centred box):", "",
                  "| channel | base | with the named effect | shrink |", "|---|---|---|---|"]  # fmt: skip
        lines += [f"| {ch} | [{r['before'][0]:.3g}, {r['before'][1]:.3g}] | [{r['after'][0]:.3g}, {r['after'][1]:.3g}] "
                  f"| {r['shrink']:.2f} |" for ch, r in ba.items()]  # fmt: skip
    if bands_after:
        lines += ["", f"Minimal trace-conformant W per |ay| band (all 2-s windows, 100 Hz): box widths, base -> "
                  f"{label}", "", "| band | w_vx | w_vy | w_omega |", "|---|---|---|---|"]  # fmt: skip
        for g, after in bands_after.items():
            before = bands_before.get(g)
            if after is None or before is None:
                continue
            cells = [f"{np.ptp(b):.3g} -> {np.ptp(a):.3g}" for b, a in zip(before, after)]
            lines.append(f"| {g.replace('|', chr(92) + '|')} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def save_report(report, out, plots=True):
    """report.json, report.md and (with ``plots``) the report's pictures into ``out/diagnosis``; the pictures' paths."""
    folder = out / "diagnosis"
    folder.mkdir(parents=True, exist_ok=True)
    report.to_json(folder / "report.json")
    atomic_write(folder / "report.md", report.summary())
    return report.save_plots(folder) if plots else []
