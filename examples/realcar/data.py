"""The real-car run as a test suite: reading, glitch repair, measurement-error box V from the data, |ay| bands.

Used by ``run.py`` (and the tests via ``load_example("realcar")``).  The
recording is ``stanford_track_100hz.csv.gz`` of ``../shared/data/realcar``
(its README gives provenance, units and the vehicle parameters).
"""

from __future__ import annotations

import gzip
import math
import re
from pathlib import Path

import numpy as np

import reachconf as rc
from reachconf.io import TestCase, TestSuite

FILE = "stanford_track_100hz.csv.gz"
COLUMNS = ("t", "delta", "delta_fl", "delta_fr", "ax", "ay", "vx", "vy", "omega", "beta")
INPUTS = ("ax", "delta")
OUTPUTS = ("vx", "vy", "omega")
#: |ay| bands [m/s^2] of the Table 3 analogue
BANDS = ((0.0, 4.0), (4.0, 8.0), (8.0, 12.0), (12.0, math.inf))
#: a steering sample further than this from the median of its neighbours is a glitch [rad] (README: the
#: road-wheel angle moves < 0.01 rad per 10 ms on this run except at 4 isolated samples that jump by ~0.5 rad)
GLITCH = 0.05
#: V = this many robust noise standard deviations (see :func:`noise_V`)
V_SIGMAS = 4.5


def band_label(lo, hi) -> str:
    return f"|ay| {lo:g}-{hi:g}" if math.isfinite(hi) else f"|ay| > {lo:g}"


def read_run(folder) -> dict:
    """The columns of the recording (SI units, as stored); DataError on a missing or malformed file."""
    path = Path(folder) / FILE
    if not Path(folder).is_dir():
        raise rc.DataError(f"{folder}: no such data folder")
    if not path.is_file():
        raise rc.DataError(f"{folder}: missing {FILE}")
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            header = fh.readline().strip().split(",")
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
    except (OSError, ValueError, EOFError) as exc:  # numpy counts data rows from 0: name the file's line
        msg = re.sub(r"row (\d+)", lambda m: f"line {int(m.group(1)) + 2}", str(exc))
        raise rc.DataError(f"{path}: cannot read ({msg})") from exc
    missing = [c for c in COLUMNS if c not in header]
    if missing or data.shape[1] != len(header) or data.shape[0] < 200:
        raise rc.DataError(f"{path}: expected columns {list(COLUMNS)} and >= 200 rows, got {header} x {data.shape}")
    bad = ~np.isfinite(data)
    if bad.any():  # the file's line (the header is line 1) and column
        r, c = np.argwhere(bad)[0]
        raise rc.DataError(f"{path}: line {r + 2}, column {header[c]!r}: {data[r, c]} ({int(bad.sum())} NaN/inf in all)")
    steps = np.flatnonzero(~(np.diff(data[:, header.index("t")]) > 0))
    if steps.size:
        raise rc.DataError(f"{path}: line {steps[0] + 3}: time does not increase ({steps.size} such steps)")
    cols = {c: data[:, header.index(c)] for c in header}
    check_units(cols, path)
    return cols


#: the slope of ay against vx * omega may lie this far (factor) from 1: the kinematics of a car on the road,
#: ay = vy' + vx omega, where vy' averages out over a run (0.992 on the recording; 0.276 with vx in km/h, 0.017 with
#: omega in deg/s)
UNITS_SLOPE = (0.5, 2.0)


def check_units(cols, path) -> None:
    """DataError unless ay, vx and omega are consistent in SI units (the README's own check: ay against vx omega)."""
    x, y = cols["vx"] * cols["omega"], cols["ay"]
    if float(np.std(x)) == 0.0:
        return  # straight ahead at constant speed: nothing to compare
    slope = float(np.polyfit(x, y, 1)[0])
    if not UNITS_SLOPE[0] <= slope <= UNITS_SLOPE[1]:
        raise rc.DataError(f"{path}: ay is {slope:.3g} times vx * omega (1 on a car, ay = vy' + vx omega): vx, "
                           "omega or ay are not in m/s, rad/s and m/s^2 (km/h? deg/s?)")  # fmt: skip


def repair_glitches(x, threshold=GLITCH):
    """Isolated one-sample spikes replaced by the mean of their neighbours; returns (repaired copy, indices)."""
    x = np.array(x, float)
    med = np.median(np.stack([x[:-2], x[1:-1], x[2:]]), axis=0)
    idx = np.flatnonzero(np.abs(x[1:-1] - med) > threshold) + 1
    x[idx] = 0.5 * (x[idx - 1] + x[idx + 1])
    return x, idx


def noise_sigma(x) -> float:
    """Robust standard deviation of white measurement noise from second differences.

    For a smooth signal sampled fast plus white noise of std ``s``, the
    second difference is dominated by the noise, ``std(d2) = sqrt(6) s``;
    the median absolute deviation (x 1.4826) ignores the few samples where
    the signal itself turns fast.  It over-estimates ``s`` a little where
    the signal's own curvature shows (conservative for V).
    """
    d2 = np.diff(np.asarray(x, float), 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


def noise_V(cols, k=V_SIGMAS):
    """Measurement-error half-widths of the outputs: ``k`` robust noise stds (dict output -> (sigma, V))."""
    return {n: (noise_sigma(cols[n]), k * noise_sigma(cols[n])) for n in OUTPUTS}


def make_suite(cols, seconds=10.0, name="realcar", start=None, stop=None) -> TestSuite:
    """The run cut into ``seconds``-long test cases (the last sample of one is the first of the next).

    Inputs ``ax, delta`` (delta with its glitches repaired), outputs ``vx,
    vy, omega``, extra ``ay``.  Group: the |ay| band of the case's 95th
    percentile of |ay| (so a group collects calm or hard driving).
    """
    t = cols["t"]
    delta, _ = repair_glitches(cols["delta"])
    dt = float(np.median(np.diff(t)))
    n = int(round(seconds / dt))
    i0 = 0 if start is None else int(np.searchsorted(t, start - 1e-9))
    i1 = t.size if stop is None else int(np.searchsorted(t, stop + 1e-9))
    cases = []
    for k, a in enumerate(range(i0, i1 - n, n)):
        sl = slice(a, a + n + 1)
        ay95 = float(np.quantile(np.abs(cols["ay"][sl]), 0.95))
        lo, hi = next(b for b in BANDS if b[0] <= ay95 < b[1])
        cases.append(TestCase(f"run_{k:03d}", band_label(lo, hi), t[sl], np.c_[cols["ax"][sl], delta[sl]],
                              np.c_[cols["vx"][sl], cols["vy"][sl], cols["omega"][sl]], INPUTS, OUTPUTS,
                              {"ay": cols["ay"][sl]}))  # fmt: skip
    if not cases:
        raise rc.DataError(f"the run is shorter than one test case of {seconds:g} s")
    return TestSuite(cases, name=name)


def band_boxes(found, suite, model):
    """Per |ay| band: the hull of the certified disturbance traces at the samples in the band.

    ``found``: the per-case :class:`reachconf.conformance.bounds.CaseBox` list
    of ``minimal_trace_bounds(..., details=True)``.  Each trace, simulated,
    stays within V of the measurements (Alg. 1's certificate), so the run is
    conformant with the operating-point dependent box ``W(|ay|)`` given here;
    a band's box is the W that band needs.  Returns band -> ([[lo, hi]] per
    disturbance, samples).
    """
    out = {}
    ay = np.concatenate([np.abs(c.extras["ay"][: len(f.W)]) for c, f in zip(suite, found)])
    W = np.concatenate([np.asarray(f.W)[: len(c.t)] for c, f in zip(suite, found)])
    for lo, hi in BANDS:
        sel = (ay >= lo) & (ay < hi)
        key = band_label(lo, hi)
        if not sel.any():
            out[key] = (None, 0)
            continue
        out[key] = ([[float(a), float(b)] for a, b in zip(W[sel].min(axis=0), W[sel].max(axis=0))], int(sel.sum()))
    return out
