"""Sim-to-real gap diagnosis, first part: *where* the gap lies (channels, time segments, conditions).

From the per-step disturbance traces of trace conformance (section 3.2.1),
:func:`locate_gap` reports

* per disturbance channel, its share of the normalised minimal box (each
  channel's width divided by the typical size of its disturbance, the median
  absolute deviation over the suite), and which outputs' errors drive it
  (rank correlation of ``|w_i|`` with each output's one-step innovation);
* in time, the segments where a channel leaves its quiet envelope (median
  +- ``envelope`` robust standard deviations over the whole suite), per case
  and per group — segments shared by most cases of a group are reported as
  "channel, t0-t1 s of every <group>";
* in operating conditions, the Spearman rank correlation of ``|w|`` with every
  measured signal (extras such as ``ay`` included) and the magnitude of its
  rate of change, and binned envelopes of ``w`` over each signal
  (:func:`binned_envelope`).

Which unmodelled effect causes the gap, and how far W shrinks once it is
modelled, is :func:`reachconf.diagnose` (this location is its ``where`` part).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from reachconf.conformance.trace import TraceOptions, trace_disturbances
from reachconf.checks import check_options
from reachconf.errors import ConformanceError, OptionsError
from reachconf.io.results import JsonResult
from reachconf.io.cases import case_arrays, suite_cases
from reachconf.model.core import require_model
from reachconf.model.outputs import evaluate_outputs
from reachconf_kernels.integrate import rk4_one_step_each

__all__ = ["GapLocation", "locate_gap", "binned_envelope", "BINS"]


@dataclass
class GapLocation(JsonResult):
    """Where the gap lies (see the module docstring).

    Attributes
    ----------
    channels : list of str
        Disturbance names.
    shares : dict channel -> float
        Share of the normalised disturbance box.
    box : dict channel -> [lo, hi]
        Hull of the per-step disturbance traces.
    segments : dict case -> list of dict
        Excursions outside the quiet envelope (``channel``, ``t0``, ``t1``).
    group_segments : dict group -> list of dict
        Excursions shared by most cases of a group (with their ``share``).
    conditions : dict channel -> dict signal -> float
        Spearman rank correlation of ``|w|`` with every measured signal.
    envelope : dict channel -> [lo, hi]
    drivers : dict channel -> dict output -> float
        Which outputs' errors drive each channel.
    binned : dict channel -> dict signal -> dict
        Binned envelopes: the measured signals (extras such as ``ay`` too)
        cut into ``BINS`` quantile bins of their value (``|value|`` for
        signals of both signs); per bin its ``edges``, the ``count`` of
        samples, the disturbance's ``lo``/``hi`` (min/max) and ``q95`` of
        ``|w|`` — how the gap depends on the operating condition.
    """

    channels: list
    shares: dict
    box: dict
    segments: dict
    group_segments: dict
    conditions: dict
    envelope: dict = field(default_factory=dict)
    drivers: dict = field(default_factory=dict)
    binned: dict = field(default_factory=dict)

    def to_dict(self):
        """All fields as JSON values."""
        return {"channels": self.channels, "shares": self.shares, "box": self.box, "envelope": self.envelope,
                "segments": self.segments, "group_segments": self.group_segments,
                "conditions": self.conditions, "drivers": self.drivers, "binned": self.binned}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict) -> "GapLocation":
        """The location from :meth:`to_dict`."""
        return cls(list(d["channels"]), dict(d["shares"]), dict(d["box"]), dict(d["segments"]),
                   dict(d["group_segments"]), dict(d["conditions"]), dict(d.get("envelope", {})),
                   dict(d.get("drivers", {})), dict(d.get("binned", {})))  # fmt: skip

    def plot(self, ax=None):
        """Channel shares of the normalised disturbance box as bars; returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(1.0 * len(self.channels) + 3, 3))
        ax.bar(self.channels, [self.shares[c] for c in self.channels], color="tab:blue")
        ax.set_ylabel("share of the normalised box")
        ax.set_title("where the gap lies: disturbance channels", fontsize=9)
        return ax

    def summary(self, top: int = 3) -> str:
        """Plain-text summary: channel shares and drivers, shared time segments, operating conditions."""
        lines = ["Share of the normalised disturbance box per channel:"]
        for ch, sh in sorted(self.shares.items(), key=lambda kv: -kv[1]):
            drv = ", ".join(f"{o} (rho {v:.2f})" for o, v in list(self.drivers.get(ch, {}).items())[:2] if v > 0.3)
            lines.append(f"  {ch}: {100 * sh:.0f} %" + (f", driven by the errors of {drv}" if drv else ""))
        for g, segs in self.group_segments.items():
            for s in segs[:top]:
                lines.append(f"  {s['channel']}, {s['t0']:.1f}-{s['t1']:.1f} s of {s['share']:.0%} of the {g} runs")
        for ch, corr in self.conditions.items():
            best = sorted(corr.items(), key=lambda kv: -abs(kv[1]))[:top]
            lines.append(f"  |{ch}| grows with " + ", ".join(f"{k} (rho {v:+.2f})" for k, v in best))
        return "\n".join(lines)


def _segments(mask, t, min_len):
    out = []
    k = 0
    n = mask.size
    while k < n:
        if mask[k]:
            j = k
            while j + 1 < n and mask[j + 1]:
                j += 1
            if t[j + 1 if j + 1 < t.size else j] - t[k] >= min_len:
                out.append((float(t[k]), float(t[min(j + 1, t.size - 1)])))
            k = j + 1
        else:
            k += 1
    return out


def locate_gap(model, suite, V=None, envelope: float = 4.0, min_duration: float = 0.2, group_share: float = 0.6,
               options: TraceOptions | None = None, traces=None) -> GapLocation:  # fmt: skip
    """Locate the sim-to-real gap of ``model`` on ``suite`` (see module docstring).

    Parameters
    ----------
    envelope : float
        Half-width of the quiet envelope in robust standard deviations
        (1.4826 x the median absolute deviation) around the median; robust, so a
        long excursion does not widen its own envelope.
    min_duration : float
        Shortest excursion reported (s).
    group_share : float
        An excursion is reported for a group when at least this share of its
        cases is outside the envelope at the same time (cases aligned at t = 0).
    """
    require_model(model, "locate_gap")
    options = check_options(options, TraceOptions, "locate_gap")
    for name, value, ok in (("envelope", envelope, lambda v: v > 0), ("min_duration", min_duration, lambda v: v >= 0),
                            ("group_share", group_share, lambda v: 0 < v <= 1)):  # fmt: skip
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or not ok(value):
            raise OptionsError(f"locate_gap: {name} out of range, got {value!r}")
    cases = suite_cases(suite, "locate_gap")
    if model.q == 0:
        raise ConformanceError(f"model {model.name!r} has no disturbances to locate")
    if traces is None:
        traces = [trace_disturbances(model, c, V=V, options=options) for c in cases]
    elif (not isinstance(traces, (list, tuple)) or len(traces) != len(cases)
          or any(getattr(r, "case", None) != c.name or not hasattr(r, "W_trace") for r, c in zip(traces, cases))):  # fmt: skip
        raise OptionsError("locate_gap: traces must hold one TraceResult per case of the suite, in its order")
    traces = {c.name: r for c, r in zip(cases, traces)}
    names = list(model.disturbance_names)
    allW = np.vstack([r.W_trace for r in traces.values()])
    med = np.median(allW, axis=0)
    mad = np.median(np.abs(allW - med), axis=0)
    scale = np.where(mad > 0, mad, np.maximum(np.std(allW, axis=0), 1e-12))
    width = (allW.max(axis=0) - allW.min(axis=0)) / scale
    total = float(width.sum())  # 0 when no case needs a disturbance anywhere: no channel holds a share of the gap
    shares = dict(zip(names, map(float, width / total if total > 0 else np.zeros_like(width))))
    box = {n: [float(a), float(b)] for n, a, b in zip(names, allW.min(axis=0), allW.max(axis=0))}
    sigma = 1.4826 * scale  # robust standard deviation (median absolute deviation)
    qlo, qhi = med - envelope * sigma, med + envelope * sigma
    env = {n: [float(a), float(b)] for n, a, b in zip(names, qlo, qhi)}

    segments = {}
    outside = {}
    for c in cases:
        W = traces[c.name].W_trace
        t = c.t
        out = (W < qlo) | (W > qhi)
        outside[c.name] = (t[:-1] - t[0], out)
        segments[c.name] = [{"channel": names[i], "t0": a, "t1": b}
                            for i in range(len(names)) for a, b in _segments(out[:, i], t - t[0], min_duration)]  # fmt: skip

    group_segments = {}
    for g, members in suite.groups().items() if hasattr(suite, "groups") else [("all", cases)]:
        if len(members) < 2:
            continue
        grid = outside[members[0].name][0]
        frac = np.zeros((grid.size, len(names)))
        for c in members:
            tc, oc = outside[c.name]
            idx = np.clip(np.searchsorted(tc, grid), 0, tc.size - 1)
            frac += oc[idx]
        frac /= len(members)
        segs = []
        for i in range(len(names)):
            for a, b in _segments(frac[:, i] >= group_share, np.append(grid, grid[-1]), min_duration):
                sel = (grid >= a) & (grid < b)
                segs.append({"channel": names[i], "t0": a, "t1": b, "share": float(frac[sel, i].mean())})
        group_segments[g] = sorted(segs, key=lambda s: -(s["t1"] - s["t0"]) * s["share"])

    from scipy.stats import spearmanr

    cols = []
    for c in cases:
        sig = {k: v[:-1] for k, v in c.signals.items()}
        dt = np.diff(c.t)
        for k, v in c.signals.items():
            sig[f"|d{k}/dt|"] = np.abs(np.diff(v) / dt)
        cols.append(sig)
    keys = [k for k in cols[0] if all(k in s for s in cols)]
    F = {k: np.concatenate([s[k] for s in cols]) for k in keys}
    conditions = {}
    for i, n in enumerate(names):
        absw = np.abs(allW[:, i])
        corr = {}
        for k, v in F.items():
            if np.ptp(v) > 0 and np.ptp(absw) > 0:
                rho = spearmanr(absw, v).statistic
                if np.isfinite(rho):
                    corr[k] = float(rho)
        conditions[n] = dict(sorted(corr.items(), key=lambda kv: -abs(kv[1])))
    drivers = _drivers(model, cases, traces, V)
    binned = {n: {k: binned_envelope(v, allW[:, i]) for k, v in F.items() if not k.startswith("|d")}
              for i, n in enumerate(names)}  # fmt: skip
    return GapLocation(names, shares, box, segments, group_segments, conditions, env, drivers, binned)


#: number of quantile bins of :func:`binned_envelope`
BINS = 5


def binned_envelope(signal, w, bins: int = BINS) -> dict:
    """Envelope of the disturbance ``w`` in quantile bins of a condition signal.

    The bins are on ``|signal|`` when the signal takes both signs (a lateral
    acceleration to the left or right loads the tyres alike), else on the
    signal.  Returns ``{"abs": bool, "bins": [{"edges", "count", "lo", "hi",
    "q95"}, ...]}`` (``q95``: 95th percentile of ``|w|`` in the bin).
    """
    s = np.asarray(signal, float)
    w = np.asarray(w, float)
    use_abs = bool(s.min() < 0 < s.max())
    x = np.abs(s) if use_abs else s
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (x >= a) & ((x < b) | (b == edges[-1]))
        if sel.any():
            out.append({"edges": [float(a), float(b)], "count": int(sel.sum()), "lo": float(w[sel].min()),
                        "hi": float(w[sel].max()), "q95": float(np.quantile(np.abs(w[sel]), 0.95))})  # fmt: skip
    return {"abs": use_abs, "bins": out}


def _drivers(model, cases, traces, V):
    """Which outputs' errors drive each disturbance channel.

    For every sample interval, the *innovation* of each output is the
    measurement minus the undisturbed one-step prediction from the fitted
    trace's state (in units of V's radius, or of the output's spread); the
    share of channel ``i`` driven by output ``j`` is the Spearman rank
    correlation of ``|w_i|`` with ``|innovation_j|`` (negative values as 0).
    """
    from scipy.stats import spearmanr

    comp = model.compiled()
    pv = model.param_vector
    absW, innov = [], []
    for c in cases:
        t, U, Y = case_arrays(model, c)
        r = traces[c.name]
        X = np.ascontiguousarray(r.X[:-1])
        Xp = rk4_one_step_each(comp.f, X, np.ascontiguousarray(U[:-1]), np.zeros((X.shape[0], model.q)),
                               np.diff(t), pv, 4)  # fmt: skip
        innov.append(Y[1:] - evaluate_outputs(model, Xp, np.ascontiguousarray(U[1:])))
        W = r.W_trace
        absW.append(np.abs(W[: X.shape[0]]))
    absW, innov = np.vstack(absW), np.vstack(innov)
    if V is not None:
        scale = 0.5 * (np.asarray(V.hi, float) - np.asarray(V.lo, float))
    else:
        scale = np.std(innov, axis=0)
    innov = np.abs(innov) / np.where(scale > 0, scale, 1.0)
    out = {}
    for i, n in enumerate(model.disturbance_names):
        d = {}
        for j, o in enumerate(model.output_names):
            if np.ptp(absW[:, i]) > 0 and np.ptp(innov[:, j]) > 0:
                rho = spearmanr(absW[:, i], innov[:, j]).statistic
                d[o] = float(max(rho, 0.0)) if np.isfinite(rho) else 0.0
        out[n] = dict(sorted(d.items(), key=lambda kv: -kv[1]))
    return out
