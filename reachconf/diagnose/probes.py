"""Which maneuver would separate two explanations the data cannot tell apart.

Both fitted candidate models are simulated from the same measured state on a
small library of *probe* maneuvers built from the data itself, and the
probe on which their predicted measurements differ most (in units of the
sensor noise) is reported:

* for each input, sines at 0.25–4 Hz around the input's median, with an
  amplitude of twice its standard deviation in the data, reduced so that the
  input's rate stays within :data:`PROBE_RATE_FACTOR` times the largest rate
  seen in the data (a probe must stay drivable: a steering-rate limit shows
  in the data);
* for each input, a step up and a step down by twice its standard deviation,
  ramped at that rate;
* for each input, a doublet: up by twice its standard deviation for half the
  probe, then down by as much (for an acceleration: accelerate, then brake —
  a speed sweep that separates speed-dependent effects and scales from
  offsets);
* for each state that the data hold far from zero and nearly constant
  (e.g. a speed), the operating point moved to 0.5x and 1.5x its median.

:func:`band_shares` adds what the data contain: the share of each input's
variance in frequency bands, so that "the data lack steering above 1 Hz" can
be read off next to the probe.
"""

from __future__ import annotations

import numpy as np

from reachconf.diagnose.fit import transformed_signals
from reachconf.model.outputs import evaluate_outputs, state_index_of_outputs
from reachconf_kernels.integrate import rk4_windows

__all__ = ["separating_probe", "band_shares", "PROBE_FREQUENCIES", "PROBE_RATE_FACTOR", "BANDS", "REFIT_PROBES",
           "MAX_PROBE_RUNS"]

#: sine probe frequencies (Hz)
PROBE_FREQUENCIES = (0.25, 0.5, 1.0, 2.0, 4.0)
#: probes may change an input this many times faster than the data's largest rate
PROBE_RATE_FACTOR = 3.0
#: probes (best point-estimate separations first) checked with the candidates refitted to each other
REFIT_PROBES = 3
#: a probe that needs more runs than this to reach the naming z does not count as separating
MAX_PROBE_RUNS = 10
#: frequency bands (Hz) of :func:`band_shares`
BANDS = ((0.0, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, 5.0))


def band_shares(data, input_name, model) -> dict:
    """Share of the (detrended) variance of an input in each band of :data:`BANDS` (Welch periodogram)."""
    from scipy.signal import welch

    j = model.input_names.index(input_name)
    num = np.zeros(len(BANDS))
    total = 0.0
    for d in data:
        u = d.U[:, j]
        dt = float(np.median(np.diff(d.t)))
        if u.size < 16:
            continue
        f, P = welch(u - np.mean(u), fs=1.0 / dt, nperseg=min(256, u.size))
        df = f[1] - f[0]
        total += float(np.sum(P) * df)
        for b, (lo, hi) in enumerate(BANDS):
            num[b] += float(np.sum(P[(f >= lo) & (f < hi)]) * df)
    return {f"{lo:g}-{hi:g} Hz": float(v / total) if total > 0 else 0.0 for (lo, hi), v in zip(BANDS, num)}


def _simulate(fit, x0, t, U):
    """Predicted measurements of a fitted candidate (input and output effects applied) at every time of ``t``
    (the first row from ``x0``), or None when the simulation diverges."""
    model = fit.model
    Ue, _ = transformed_signals(model, fit.candidate, fit.effect_params, t, U, np.zeros((t.size, model.p)))
    comp = model.compiled()
    X = rk4_windows(comp.f, np.ascontiguousarray(x0[None, :]), np.zeros(1, dtype=np.int64), np.ascontiguousarray(Ue),
                    t, model.param_vector, model.q, t.size - 1, 2, False)[0]  # fmt: skip
    X = np.vstack([np.asarray(x0, dtype=float)[None, :], X])
    plain = state_index_of_outputs(model)
    Y = X[:, plain] if plain is not None else evaluate_outputs(model, X, Ue)
    for e, tgt in fit.candidate.parts:
        if e.kind == "output":
            i = model.output_names.index(tgt)
            Y[:, i] = e.apply_signal(t, Y[:, i], fit.effect_params[(e.name, tgt)])
    return Y if np.all(np.isfinite(Y)) else None


def _probes(model, data, horizon):
    U = np.vstack([d.U for d in data])
    dt = float(np.median(np.diff(data[0].t)))
    t = np.round(np.arange(0.0, horizon + 0.5 * dt, dt), 12)
    u0 = np.median(U, axis=0)
    amp = 2.0 * np.std(U, axis=0)
    amp = np.where(amp > 0, amp, 1.0)
    # largest rate of change in the data (smoothed over 0.1 s so that sensor noise does not count)
    k = max(int(round(0.1 / dt)), 1)
    rates = np.vstack([np.abs(np.diff(d.U[::k], axis=0)) / (k * dt) for d in data if d.U.shape[0] > k])
    rate = PROBE_RATE_FACTOR * np.percentile(rates, 99.5, axis=0) if rates.size else np.full(model.m, np.inf)
    out = []
    for j, name in enumerate(model.input_names):
        for f in PROBE_FREQUENCIES:
            a = float(min(amp[j], rate[j] / (2 * np.pi * f))) if rate[j] > 0 else float(amp[j])
            Up = np.tile(u0, (t.size, 1))
            Up[:, j] += a * np.sin(2 * np.pi * f * t)
            out.append(({"kind": "sine", "input": name, "frequency_hz": f, "amplitude": a,
                         "text": f"a {f:g} Hz sine on {name} (amplitude {a:.3g})"}, None, Up))  # fmt: skip
        for sign in (1.0, -1.0):
            Up = np.tile(u0, (t.size, 1))
            ramp = np.clip((t - 0.5) * rate[j], 0.0, amp[j]) if np.isfinite(rate[j]) and rate[j] > 0 else \
                np.where(t >= 0.5, amp[j], 0.0)  # fmt: skip
            Up[:, j] += sign * ramp
            out.append(({"kind": "step", "input": name, "size": float(sign * amp[j]), "rate": float(rate[j]),
                         "text": f"a step of {sign * amp[j]:+.3g} on {name} (at the rate {rate[j]:.3g}/s)"}, None,
                        Up))  # fmt: skip
        Up = np.tile(u0, (t.size, 1))
        half = 0.5 * horizon
        if np.isfinite(rate[j]) and rate[j] > 0:
            up = np.clip((t - 0.25) * rate[j], 0.0, amp[j])
            down = np.clip((t - half) * rate[j], 0.0, 2 * amp[j])
            Up[:, j] += up - down
        else:
            Up[:, j] += np.where(t < half, amp[j], -amp[j])
        out.append(({"kind": "doublet", "input": name, "size": float(amp[j]), "rate": float(rate[j]),
                     "text": f"a doublet on {name}: {amp[j]:+.3g} for {half:g} s, then {-amp[j]:+.3g} "
                             f"(at the rate {rate[j]:.3g}/s)"}, None, Up))  # fmt: skip
    Ys = np.vstack([d.Ys[d.starts] for d in data])
    med, spread = np.median(Ys, axis=0), np.std(Ys, axis=0)
    for i, name in enumerate(model.output_names):
        if name in model.state_names and abs(med[i]) > 5 * spread[i] > 0:
            for factor in (0.5, 1.5):
                out.append(({"kind": "operating_point", "state": name, "value": float(factor * med[i]),
                             "text": f"runs at {name} = {factor * med[i]:.3g} ({factor:g}x the data's {med[i]:.3g})"},
                            (model.state_names.index(name), factor * med[i]), np.tile(u0, (t.size, 1))))  # fmt: skip
    return t, out


def _start_outputs(model, data):
    """The measured (smoothed) outputs at a window start near the data's median operating point, or None when the
    states cannot be read from the outputs."""
    from reachconf.model.outputs import output_index_of_states

    direct = output_index_of_states(model)
    if direct is None:
        return None
    Y = np.vstack([d.Ys[d.starts] for d in data])
    X = Y[:, direct]
    med = np.median(X, axis=0)
    scale = np.std(X, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    return Y[int(np.argmin(np.sum(((X - med) / scale) ** 2, axis=1)))].copy()


def _true_state(fit, y):
    """The state a fitted candidate reads from the measured outputs ``y``: its sensor effects undone (last first)."""
    from reachconf.model.outputs import output_index_of_states

    model = fit.model
    y = np.array(y, dtype=float)
    for e, tgt in reversed(fit.candidate.parts):
        if e.kind == "output":
            i = model.output_names.index(tgt)
            y[i] = float(e.inverse(np.array([y[i]]), fit.effect_params[(e.name, tgt)])[0])
    return y[output_index_of_states(model)]


def separating_probe(fit_a, fit_b, data, sigma, horizon: float = 3.0, refit=None, z: float = 3.0) -> dict | None:
    """The probe maneuver that would separate two fitted candidates.

    Both start from the same measured outputs (each model's state read from them through its own sensor
    effects) and are simulated on every probe; the probes are ranked by the rms difference of the two
    predictions (noise units).  With ``refit``, the :data:`REFIT_PROBES` best are checked the way the data were
    (:func:`reachconf.diagnose.separable.probe_mimic_losses`): ``fit_b``'s candidate is refitted to ``fit_a``'s
    predictions on the suite *and* on the probe, and only what it then cannot reproduce on the probe counts —
    two point estimates that differ within their own uncertainty are not separated.  One run of a probe with
    remaining squared differences ``D`` (noise units) gives an expected held-out z of ``sqrt(D) / 2``
    (the loss difference ``D`` against its noise standard deviation ``2 sqrt(D)``); ``runs`` is the number of
    runs that brings it to ``z``.

    Parameters
    ----------
    fit_a, fit_b : FitResult
        The chosen model and an explanation the data cannot tell from it.
    data : list of PreparedCase
    sigma : ndarray
        Noise level of every output.
    horizon : float
        Length of a probe, seconds.
    refit : callable, optional
        ``refit([(t, U, Y), ...]) -> [(D, n), ...]``: the part of ``fit_a``'s predictions ``Y`` on each probe
        that ``fit_b``'s candidate cannot reproduce (squared differences in noise units over the ``n`` compared
        samples of the probe's prediction windows); None: rank by the point estimates alone.
    z : float
        The held-out z a probe must be expected to reach (:attr:`DiagnoseOptions.z_name`).

    Returns
    -------
    dict or None
        None when the models' states cannot be read from the outputs.  Otherwise ``probe`` (``kind``,
        input/state, frequency/size/value, ``text``; None when no probe separates them: within
        :data:`MAX_PROBE_RUNS` runs with ``refit``, or squared differences summing to under one noise variance
        without), ``separation`` (rms difference of the point estimates on it, noise units), and with ``refit``
        ``refit_separation`` (rms after the refit), ``expected_z`` (one run) and ``runs``; ``ranking``: the five
        best probes by ``separation``.
    """
    y_start = _start_outputs(fit_a.model, data)
    if y_start is None or fit_a.model.n != fit_b.model.n:
        # different state spaces (a model effect added states): start both from the shared states
        return None
    # the same measured start is a different true state for a model with a sensor effect
    xa_start, xb_start = _true_state(fit_a, y_start), _true_state(fit_b, y_start)
    t, probes = _probes(fit_a.model, data, horizon)
    scored = []
    for info, shift, Up in probes:
        xa, xb = xa_start.copy(), xb_start.copy()
        if shift is not None:
            xa[shift[0]] = xb[shift[0]] = shift[1]
        Ya, Yb = _simulate(fit_a, xa, t, Up), _simulate(fit_b, xb, t, Up)
        if Ya is None or Yb is None:
            continue
        r2 = ((Ya[1:] - Yb[1:]) / sigma) ** 2
        scored.append((float(np.sqrt(np.mean(r2))), float(np.sum(r2)), info, (t, Up, Ya)))
    if not scored:
        return None
    scored.sort(key=lambda s: -s[0])
    ranking = [{"text": i["text"], "separation": s} for s, _, i, _ in scored[:5]]
    if refit is None:
        sep, total, info, _ = scored[0]
        # one run of the best probe would not show the two apart by even one noise std in all: none separates them
        return {"probe": info if total >= 1.0 else None, "separation": sep, "horizon": horizon, "ranking": ranking}
    top = [s for s in scored[:REFIT_PROBES] if s[1] >= 1.0]  # (under one noise variance: nothing to refit away)
    found = refit([s[3] for s in top]) if top else []
    best = max(range(len(top)), key=lambda k: found[k][0], default=None)
    if best is None:
        return {"probe": None, "separation": scored[0][0], "horizon": horizon, "ranking": ranking,
                "refit_separation": 0.0, "expected_z": 0.0, "runs": None}  # fmt: skip
    d, n = max(float(found[best][0]), 0.0), found[best][1]
    sep, total, info, _ = top[best]
    runs = int(np.ceil(4.0 * z * z / d)) if d > 0 else None
    runs = runs if runs is not None and runs <= MAX_PROBE_RUNS else None
    return {"probe": info if runs is not None else None, "separation": sep, "horizon": horizon, "ranking": ranking,
            "refit_separation": float(np.sqrt(d / n)) if n > 0 else 0.0,
            "expected_z": 0.5 * float(np.sqrt(d)), "runs": runs}  # fmt: skip
