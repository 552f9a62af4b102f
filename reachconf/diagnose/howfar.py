"""How far the gap shrinks: minimal disturbance boxes, reach tubes and the actuator-vs-process check.

Helpers of :func:`reachconf.diagnose` for its *where* and *how far* parts:
the minimal trace-conformant ``W`` (SCP of synthesis step 2) and ``V`` boxes
of held-out cases cut into segments, their shrink, X–Y reach tubes before and
after, the reachset-conformant ``W`` (steps 1–3 and the α-search), and the
comparison of a model driven by measured actuator signals with one driven by
the requests (Figure 1 of the source report).
"""

from __future__ import annotations

import numpy as np

from reachconf.conformance.bounds import case_box
from reachconf.conformance.synthesis import SynthesisOptions, synthesize_W
from reachconf.conformance.trace import TraceOptions
from reachconf.diagnose.fit import case_starts, noise_level, transformed_case
from reachconf.errors import ReachconfError
from reachconf.io.cases import TestCase, TestSuite
from reachconf.model.outputs import output_index_of_states
from reachconf.reach import reach
from reachconf.reach_options import ReachOptions
from reachconf.sets.core import Interval

__all__ = ["minimal_box", "measurement_box", "decimated_cases", "segments_of", "box_size", "box_shrink",
           "actuator_vs_process", "reach_tubes", "reachset_W"]  # fmt: skip


def minimal_box(model, cases, V):
    """Hull of the per-case minimal W boxes (SCP of synthesis step 2, best effort: the base model may admit no
    trace at all), or None if the SCP fails."""
    los, his = [], []
    if not cases:
        return None
    try:
        for c in cases:
            r = case_box(model, c, V, "optctrl", "W", TraceOptions(), certify=False)
            los.append(r.lo)
            his.append(r.hi)
    except (ReachconfError, np.linalg.LinAlgError, ValueError):
        return None
    return np.min(los, axis=0), np.max(his, axis=0)


def measurement_box(model, cases):
    """Hull of the per-case minimal V boxes with W = 0 (SCP), or None."""
    try:
        rs = [case_box(model, c, None, "perstep", "V", TraceOptions()) for c in cases]
    except (ReachconfError, np.linalg.LinAlgError, ValueError):
        return None
    if not rs:
        return None
    return np.min([r.lo for r in rs], axis=0), np.max([r.hi for r in rs], axis=0)


def decimated_cases(model, fit, cases, k, segment=None, substeps=None):
    """Held-out cases as the candidate model sees them, decimated; cut into ``segment``-second pieces if given.

    The minimal box of a whole open-loop trace is dominated by the drift that
    small errors build up over many seconds; boxes of short segments (each
    free to start anywhere in the measurement's V) measure what the effect
    changes.  A lag starts each case where it fits it best (:func:`case_starts`,
    with ``substeps`` RK4 steps per sample; None: :func:`~reachconf.diagnose.residuals.steps_per_sample`).
    """
    out = []
    memory = any(e.start is not None for e, _ in fit.candidate.inputs)
    for d in cases:
        starts = None
        if memory:
            sigma = np.maximum(noise_level(d.Y), 1e-12)
            starts = case_starts(fit.model, fit.candidate, fit.effect_params, d, sigma, substeps)[0]
        c = transformed_case(model, d.case, fit.candidate, fit.effect_params, starts)
        out += segments_of(c.decimate(k) if k > 1 else c, segment)
    return out


def segments_of(c, segment):
    """A case cut into pieces of ``segment`` seconds (the last one at least half as long); ``[c]`` for None
    and for a case shorter than half a segment (taken whole)."""
    if segment is None or c.t[-1] - c.t[0] < 0.5 * segment:
        return [c]
    out = []
    t0, t_end = float(c.t[0]), float(c.t[-1])
    while t0 + 0.5 * segment <= t_end:
        t1 = min(t0 + segment, t_end)
        out.append(c.segment(t0, t1))
        t0 = t1
    return out


def box_size(box):
    """Widths of the smallest box centred at ``w = 0`` that contains ``box``.

    The disturbance a model needs is measured from its nominal ``w = 0``: an
    unmodelled constant (an offset) moves the minimal box away from 0 without
    widening it, so raw widths would not see it.
    """
    return 2.0 * np.maximum(np.abs(box[0]), np.abs(box[1]))


def box_shrink(base_box, box, eps, channels):
    """Volume and per-channel shrink of the zero-centred box sizes (``eps`` per channel guards empty channels)."""
    per = (box_size(base_box) + eps) / (box_size(box) + eps)
    return float(np.prod(per)), dict(zip(channels, map(float, per)))


def actuator_vs_process(model, fit, cases, V, k, segment, threshold: float = 1.0):
    """Figure 1: the base model driven by measured actuator outputs vs by (affinely mapped) requests.

    The gap is said to sit in the actuators when driving by the requests needs a ``W`` volume at least
    ``threshold`` times larger.
    """
    req = {u: f"{u}_req" for u in model.input_names}
    have = [u for u in model.input_names if all(req[u] in d.case.signals for d in cases)]
    if not have:
        return None
    measured = decimated_cases(model, fit, cases, k, segment)
    requested = []
    maps = {}
    for u in have:
        j = model.input_names.index(u)
        A = np.concatenate([d.case.signal(req[u]) for d in cases])
        B = np.concatenate([d.U[:, j] for d in cases])
        if np.ptp(A) > 1e-12 * max(1.0, float(np.max(np.abs(A)))):
            coef = np.polyfit(A, B, 1)
        else:  # a constant request fixes no gain: the map keeps it and moves the request by the mean offset
            coef = (1.0, float(np.mean(B - A)))
        maps[u] = [float(coef[0]), float(coef[1])]
    for d in cases:
        c = d.case.with_requests(maps, inputs=have)
        requested += segments_of(c.decimate(k) if k > 1 else c, segment)
    bm = minimal_box(fit.model, measured, V)
    br = minimal_box(fit.model, requested, V)
    if bm is None or br is None:
        return None
    eps = 1e-9 + 0.05 * np.maximum(box_size(bm), box_size(br))
    ratio, per = box_shrink(br, bm, eps, model.disturbance_names)
    side = "actuators" if ratio >= threshold else "process model"
    verdict = (f"with the requested instead of the measured actuator signals ({', '.join(have)}) the minimal W "
               f"volume is {ratio:.2f}x " + ("larger" if ratio >= 1 else "as large") + f": the gap sits mostly in the "
               f"{side}")  # fmt: skip
    return {"inputs": have, "request_map": maps, "volume_ratio": ratio, "per_channel_ratio": per,
            "box_measured": [list(map(float, bm[0])), list(map(float, bm[1]))],
            "box_requested": [list(map(float, br[0])), list(map(float, br[1]))], "verdict": verdict}  # fmt: skip


def reach_tubes(model, fits_boxes, case_of, horizon, V):
    """X-Y (first two states) reach tubes of one held-out case, base and best model on the same axes."""
    tubes = []
    for label, fit, box in fits_boxes:
        c = case_of(fit)
        keep = c.t <= c.t[0] + horizon + 1e-9
        t, U, Y = c.t[keep], np.asarray(c.U, float)[keep], np.asarray(c.Y, float)[keep]
        direct = output_index_of_states(fit.model)
        if direct is None:
            return []
        X0 = Interval(Y[0, direct] - V.hi[direct], Y[0, direct] - V.lo[direct])  # eq. 67: y = x + v
        try:
            tube = reach(fit.model, X0, t, inputs=U, W=Interval(box[0], box[1]), options=ReachOptions(progress=False))
        except ReachconfError as exc:
            tubes.append({"label": label, "error": str(exc)})
            continue
        tubes.append({"label": label, "tube": tube, "measured": Y[:, direct[:2]]})
    return tubes


def reachset_W(model, segments, V):
    """Reachset-conformant W of the held-out segments (synthesis steps 1-3 and the merge, one group)."""
    cases = [TestCase(c.name, "held-out", np.array(c.t), np.array(c.U), np.array(c.Y), c.input_names, c.output_names)
             for c in segments]  # fmt: skip
    try:
        res = synthesize_W(model, TestSuite(cases), V, SynthesisOptions(), progress=False)
    except ReachconfError as exc:
        return None, str(exc)
    box = res.groups["held-out"]
    return (np.asarray(box.lo, float), np.asarray(box.hi, float)), bool(res.group_conformant["held-out"])


