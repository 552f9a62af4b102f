"""A real car on a race track (Stanford data, 100 Hz): conformance of the single-track model and its gap.

    python examples/realcar/run.py --data ../shared/data/realcar --out DIR [--workers N] [--quick] [--no-diagnosis]

The recording (550 s, measured; ``../shared/data/realcar/README.md``) and the
built-in model ``single_track`` (linear tyres, the README's parameters):

1. the suite: the run cut into 10-s test cases (inputs ``ax, delta``, outputs
   ``vx, vy, omega``, extra column ``ay``), written to ``DIR/suite`` in the
   documented folder format (``suite.toml`` + one CSV per case).  Four
   isolated one-sample steering glitches (~0.5 rad jumps) are repaired first;
2. the measurement-error box V from the data: ``V_SIGMAS`` robust standard
   deviations of the high-frequency noise of each output (second differences,
   median absolute deviation; :func:`data.noise_sigma`);
3. Table 3 analogue at 100 Hz: the minimal trace-conformant W (Alg. 2's
   trace, then the box SCP; every box certified by Alg. 1) on the 2-s
   segments of the cases, per |ay| band of the segment's peak |ay| (0-4, 4-8,
   8-12, > 12 m/s^2) and their hull (the whole run);
4. reachset conformance (eq. 43) of the same 2-s windows, driven by the
   measured inputs, with V and three synthesised W: each window's own minimal
   trace-conformant box, its band's box and the whole-run box; the share of
   conformant (and undecided: the reach left the model's domain vx > 0)
   windows; reach tubes of vy and omega against time with the measurements
   for the calmest and the hardest 10-s case (``tube_calm.png``,
   ``tube_hard.png``); W per band as a chart (``W_bands.png``);
5. the gap diagnosis ``rc.diagnose(single_track(), suite)`` with the tyre
   effect ``tire_fiala`` and steering / sensor effects as candidates
   (``diagnosis.py``; skipped with ``--no-diagnosis``): its report in
   ``DIR/diagnosis``, and the Table-3 boxes per band again with the named
   effect.

Steps 3-4 and the Table-3 boxes after the diagnosis run on ``--workers``
local processes (default :func:`default_workers`: the machine's cores, at
most :data:`MAX_DEFAULT_WORKERS`; ``--workers 1`` runs everything in this
process).  Writes ``DIR/realcar.json``, ``DIR/realcar.md`` and the pictures;
timings are wall and CPU seconds of this process (workers' CPU not included).  Bad
``--data``: one-line error, exit 2.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from data import BANDS, V_SIGMAS, band_label, make_suite, noise_V, read_run, repair_glitches  # noqa: E402
from jobs import reachset_job  # noqa: E402

import reachconf as rc  # noqa: E402
from reachconf.io import TestSuite, atomic_write, json_text, save_suite  # noqa: E402
from reachconf.script import caused_by_ctrl_c  # noqa: E402
from reachconf.models import single_track  # noqa: E402
from reachconf.plot import save_figure  # noqa: E402
from reachconf.runner import Pool, run_cases  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[2]
#: length of the test cases and of the Table-3 segments / reachset windows [s]
CASE_SECONDS, WINDOW_SECONDS = 10.0, 2.0
#: --quick: the first 60 s of the run (the test suite's run)
QUICK_SECONDS = 60.0


#: the default number of worker processes is the machine's cores, but at most this many (each holds ~0.3 GB)
MAX_DEFAULT_WORKERS = 4


def default_workers() -> int:
    """Worker processes when ``--workers`` is not given: ``min(cores, MAX_DEFAULT_WORKERS)``."""
    return max(1, min(os.cpu_count() or 1, MAX_DEFAULT_WORKERS))


def default_data() -> Path:
    root = os.environ.get("REACHCONF_DATA")
    return (Path(root) if root else REPO_ROOT.parent / "shared" / "data") / "realcar"


def pairs(W):
    return [[float(a), float(b)] for a, b in zip(W.lo, W.hi)]


def windows(suite, seconds=WINDOW_SECONDS) -> TestSuite:
    """The cases cut into ``seconds``-long windows, grouped by the |ay| band of each window's peak |ay|."""
    out = []
    for case in suite:
        for w in case.segments(seconds, partial=False):
            peak = float(np.max(np.abs(w.extras["ay"])))
            lo, hi = next(b for b in BANDS if b[0] <= peak < b[1])
            out.append(type(w)(w.name, band_label(lo, hi), w.t, w.U, w.Y, w.input_names, w.output_names, w.extras))
    return TestSuite(out, name=f"{suite.name}_{seconds:g}s")


def table3(model, wins, V, pool):
    """Minimal trace-conformant W per |ay| band (certified boxes) and the hull over the bands (the whole run)."""
    out, counts, methods, own = {}, {}, {}, {}
    groups = wins.groups()
    for lo, hi in BANDS:
        g = band_label(lo, hi)
        members = groups.get(g, [])
        counts[g] = len(members)
        if not members:
            out[g] = None
            continue
        box, found = rc.minimal_trace_bounds(model, TestSuite(members, name=g), V=V, method="optctrl",
                                             executor=pool, details=True)  # fmt: skip
        out[g] = pairs(box)
        methods[g] = sorted({f.method for f in found})
        own.update({c.name: rc.Interval(f.lo, f.hi) for c, f in zip(members, found)})
    boxes = [np.array(b) for b in out.values() if b is not None]
    out["whole run"] = np.stack([np.min([b[:, 0] for b in boxes], axis=0), np.max([b[:, 1] for b in boxes], axis=0)],
                                axis=1).tolist()  # fmt: skip
    return out, counts, methods, own


def box_of(rows):
    rows = np.asarray(rows, float)
    return rc.Interval(rows[:, 0], rows[:, 1])


def reachset_windows(model, wins, W_of, V, pool):
    """Reachset conformance (eq. 43) of every window with ``W_of(window)`` and V; per band the share of conformant windows."""
    jobs = [(model, c, W_of(c), V) for c in wins]
    res = run_cases(reachset_job, jobs, desc="reachset windows", pool=pool)
    by_band = {}
    for c, r in zip(wins, res):
        by_band.setdefault(c.group, []).append(r)
    share = {g: {"conformant": sum(r["verdict"] == "conformant" for r in rs),
                 "undecided": sum(r["verdict"] == "undecided" for r in rs), "windows": len(rs)}
             for g, rs in by_band.items()}  # fmt: skip
    share["all"] = {k: sum(v[k] for v in share.values()) for k in ("conformant", "undecided", "windows")}
    return share, res


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_stretch(model, case, W_of, V, path, title):
    """vy and omega reach tubes of consecutive 2-s windows of one case against time, with the measurements."""
    from reachconf.conformance import reachset_conformance

    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    for win in case.segments(WINDOW_SECONDS, partial=False):
        a = win.t[0]
        r = reachset_conformance(model, win, W_of(win), V, progress=False)
        if r.tube is None:  # the reach failed (undecided): nothing to draw for this window
            continue
        b, ti = r.tube.bounds(), r.tube.time_intervals
        tt = np.asarray(ti, float).ravel() + win.t[0]  # the tube's times start at 0 in each window
        for ax, (k, name) in zip(axes, ((1, "vy"), (2, "omega"))):
            lo, hi = np.repeat(b[:, 0, k], 2), np.repeat(b[:, 1, k], 2)
            first = not ax.collections
            ax.fill_between(tt, lo + V.lo[k], hi + V.hi[k], color="C1", alpha=0.25, lw=0,
                            label="reach tube ⊕ V" if first else None)  # fmt: skip
            ax.fill_between(tt, lo, hi, color="C0", alpha=0.45, lw=0, label="reach tube" if first else None)
            ax.axvline(a, color="0.6", lw=0.5)
        bad = ~np.asarray(r.inside, bool)
        for ax, k in zip(axes, (1, 2)):
            if bad.any():
                ax.plot(win.t[bad], win.Y[bad, k], "r.", ms=4)
    for ax, k, unit in zip(axes, (1, 2), ("vy [m/s]", "omega [rad/s]")):
        ax.plot(case.t, case.Y[:, k], "k-", lw=0.8, label="measured")
        ax.set_ylabel(unit)
    axes[0].legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, bbox_inches=None)
    plt.close(fig)
    return str(path)


def plot_bands(tab, counts, path):
    """Half-widths of the minimal W per band and channel (bar chart)."""
    plt = _pyplot()
    names = ("w_vx [m/s²]", "w_vy [m/s²]", "w_omega [rad/s²]")
    bands = [g for g in tab if g != "whole run" and tab[g] is not None]
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4))
    for k, ax in enumerate(axes):
        lo = [-tab[g][k][0] for g in bands]
        hi = [tab[g][k][1] for g in bands]
        x = np.arange(len(bands))
        ax.bar(x - 0.2, lo, 0.4, label="−lower bound", color="C0")
        ax.bar(x + 0.2, hi, 0.4, label="upper bound", color="C3")
        ax.set_xticks(x, [f"{g}\n({counts[g]} win.)" for g in bands], fontsize=7)
        ax.set_title(names[k], fontsize=9)
    axes[0].legend(fontsize=7)
    fig.suptitle("Minimal trace-conformant W per |ay| band [m/s²] (2-s windows, 100 Hz)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, bbox_inches=None)
    plt.close(fig)
    return str(path)


def _md(text) -> str:
    return str(text).replace("|", "\\|")


def markdown(result) -> str:
    """realcar.md: V, the Table 3 analogue, the reachset shares and the timings."""
    lines = ["# Real car (Stanford track data, 100 Hz): single_track with linear tyres", ""]
    v = result["V"]
    lines += ["## Measurement error V (from the data)", "", "| output | noise σ | V = ±%g σ |" % v["sigmas"],
              "|---|---|---|"]  # fmt: skip
    lines += [f"| {n} | {s:.3g} | {h:.3g} |" for n, (s, h) in v["per_output"].items()]
    lines += ["", "## Table 3 analogue: minimal trace-conformant W at 100 Hz (2-s windows by peak |ay|)", "",
              "| band | windows | w_vx [m/s²] | w_vy [m/s²] | w_omega [rad/s²] |", "|---|---|---|---|---|"]
    for g, b in result["table3"].items():
        n = result["table3_windows"].get(g, sum(result["table3_windows"].values()))
        cells = ["—"] * 3 if b is None else [f"[{lo:.3g}, {hi:.3g}]" for lo, hi in b]
        lines.append(f"| {_md(g)} | {n} | " + " | ".join(cells) + " |")
    rs = result.get("reachset")
    if rs:
        rb, rr = result["reachset_band_W"], result["reachset_whole_run_W"]
        lines += ["", "## Reachset conformance of the 2-s windows (measured inputs, V above)", "",
                  "conformant / undecided (the reach left the region vx > 0 where the model is defined) windows", "",
                  "| band | windows | window's own minimal W | band's W | whole-run W |", "|---|---|---|---|---|"]
        lines += [f"| {_md(g)} | {s['windows']} | " + " | ".join(f"{x[g]['conformant']} / {x[g]['undecided']}"
                                                                   for x in (rs, rb, rr)) + " |"
                  for g, s in rs.items()]  # fmt: skip
    if "diagnosis_markdown" in result:
        lines += ["", result["diagnosis_markdown"]]
    lines += ["", "## Timings [s] (wall / CPU of this process)", "", "| step | wall | CPU |", "|---|---|---|"]
    lines += [f"| {k} | {w:.1f} | {c:.1f} |" for k, (w, c) in result["timings"].items()]
    return "\n".join(lines) + "\n"


class _Clock:
    def __init__(self, timings):
        self.timings = timings

    def __call__(self, key):
        self.key, self.w, self.c = key, time.perf_counter(), time.process_time()
        return self

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.timings[self.key] = (time.perf_counter() - self.w, time.process_time() - self.c)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="data folder (default: ../shared/data/realcar from the repo root)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--workers", type=int, default=None,
                    help=f"local worker processes (default: the machine's cores, at most {MAX_DEFAULT_WORKERS})")
    ap.add_argument("--quick", action="store_true", help=f"only the first {QUICK_SECONDS:g} s of the run")
    ap.add_argument("--no-diagnosis", action="store_true", help="stop after the conformance tables")
    ap.add_argument("--no-plots", action="store_true")
    args = ap.parse_args(argv)
    data = Path(args.data) if args.data else default_data()
    out = Path(args.out)
    timings = {}
    clock = _Clock(timings)
    try:
        cols = read_run(data)
        out.mkdir(parents=True, exist_ok=True)
    except (rc.ReachconfError, OSError) as exc:
        print(f"realcar: error: {exc}", file=sys.stderr)
        return 2
    result = {"data": str(data)}
    if args.workers is not None and args.workers < 1:
        print(f"realcar: error: --workers must be >= 1, got {args.workers}", file=sys.stderr)
        return 2
    pool = Pool(args.workers if args.workers is not None else default_workers())
    try:
        with clock("suite and V"):
            stop = cols["t"][0] + QUICK_SECONDS if args.quick else None
            suite = make_suite(cols, CASE_SECONDS, stop=stop)
            save_suite(suite, out / "suite", replace=True)
            _, glitches = repair_glitches(cols["delta"])
            vd = noise_V(cols)
            half = np.array([h for _, h in vd.values()])
            V = rc.Interval(-half, half)
            wins = windows(suite)
        result.update(cases=len(suite), case_seconds=CASE_SECONDS, window_seconds=WINDOW_SECONDS,
                      steering_glitches_repaired_at=[float(cols["t"][i]) for i in glitches],
                      V={"sigmas": V_SIGMAS, "per_output": vd})  # fmt: skip
        print(f"1-2. {len(suite)} cases of {CASE_SECONDS:g} s, {len(wins)} windows; V = "
              + ", ".join(f"{n} ±{h:.3g}" for n, (_, h) in vd.items()), flush=True)
        car = single_track()
        with clock("table 3"):
            tab, counts, methods, own_W = table3(car, wins, V, pool)
        result.update(table3=tab, table3_windows=counts, table3_methods=methods)
        print("3. Table 3: " + "; ".join(f"{g}: {b}" for g, b in tab.items()), flush=True)
        W_run = box_of(tab["whole run"])
        band_W = {g: box_of(b) for g, b in tab.items() if b is not None}

        def W_band(c):
            return band_W[c.group]

        def W_own(c):
            return own_W[c.name]

        with clock("reachset windows"):
            share, per_window = reachset_windows(car, wins, W_own, V, pool)
            share_band, _ = reachset_windows(car, wins, W_band, V, pool)
            share_run, _ = reachset_windows(car, wins, lambda c: W_run, V, pool)
        result.update(reachset=share, reachset_band_W=share_band, reachset_whole_run_W=share_run,
                      reachset_windows=per_window)  # fmt: skip
        print("4. reachset (conformant / undecided of " + str(share["all"]["windows"]) + " windows): "
              + ", ".join(f"{k} {s['all']['conformant']} / {s['all']['undecided']}"
                          for k, s in (("own W", share), ("band W", share_band), ("whole-run W", share_run))),
              flush=True)  # fmt: skip
        if not args.no_plots:
            with clock("pictures"):
                peak = [float(np.max(np.abs(c.extras["ay"]))) for c in suite]
                calm, hard = suite[int(np.argmin(peak))], suite[int(np.argmax(peak))]
                result["pictures"] = [
                    plot_stretch(car, calm, W_own, V, out / "tube_calm.png",
                                 f"calm stretch ({calm.name}, peak |ay| {min(peak):.1f} m/s²): vy, omega reach tubes"),
                    plot_stretch(car, hard, W_own, V, out / "tube_hard.png",
                                 f"hard stretch ({hard.name}, peak |ay| {max(peak):.1f} m/s²): vy, omega reach tubes"),
                    plot_bands(tab, counts, out / "W_bands.png")]  # fmt: skip
        if not args.no_diagnosis:
            from diagnosis import as_seen_by_model, diagnosis_markdown, named_model, run_diagnosis, save_report

            with clock("diagnosis"):
                report = run_diagnosis(car, suite, V, progress=True)
                result["diagnosis"] = report.to_dict()
                print(f"5. diagnosis: {report.verdict}", flush=True)
                fitted, parts, named, signal = named_model(car, report)
                bands_after, label = None, ""
                if parts:  # how far: Table 3 again with the named (else the best scored) effects
                    label = (("named: " if named else "best scored, not named: ")
                             + " + ".join(f"{e}({g}) " + ", ".join(f"{k}={v:.3g}" for k, v in p.items())
                                          for e, g, p in parts))  # fmt: skip
                    wins_after = windows(as_seen_by_model(car, suite, signal)) if signal else wins
                    bands_after, _, _, _ = table3(fitted, wins_after, V, pool)
                    result["table3_after"] = {"model": label, "named": named, "table": bands_after}
                result["diagnosis_markdown"] = diagnosis_markdown(report, tab, bands_after, label)
                result["diagnosis_pictures"] = save_report(report, out, plots=not args.no_plots)
    except (KeyboardInterrupt, SystemError) as exc:  # Ctrl-C (the pool's Interrupted; in compiled code a SystemError)
        if not (isinstance(exc, KeyboardInterrupt) or caused_by_ctrl_c(exc)):
            raise
        result["timings"] = timings
        atomic_write(out / "realcar.partial.json", json_text(result))
        print(f"realcar: interrupted; the finished parts are in {out / 'realcar.partial.json'}", file=sys.stderr)
        raise
    except (rc.ReachconfError, OSError) as exc:
        print(f"realcar: error: {exc}", file=sys.stderr)
        return 2
    finally:
        pool.close()
    result["timings"] = timings
    atomic_write(out / "realcar.json", json_text(result))
    atomic_write(out / "realcar.md", markdown(result))
    print("timings [s] (wall, CPU): " + ", ".join(f"{k} {w:.1f}/{c:.1f}" for k, (w, c) in timings.items()))
    print(f"wrote {out / 'realcar.json'} and {out / 'realcar.md'}")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    from reachconf.script import run_script

    sys.exit(run_script(main, "realcar"))
