"""A user's first run: ``reachconf demo`` with nothing compiled, against a baseline commit in the same run.

Each run is a fresh process with an empty numba cache (``NUMBA_CACHE_DIR``) and an
empty model cache (``REACHCONF_CACHE``), so it pays for what a fresh installation
pays: compiling the package's kernels and generating and compiling the demo's
model.  Then the same command again on the now warm caches.  "Before" is the
tree of a baseline commit (default: 91de396, before the reach kernels' call
signatures were made single), extracted with ``git archive`` and run on the
same machine in the same run; "after" is this checkout::

    python benchmarks/bench_first_run.py [--baseline REF | --no-baseline] [--repeat 1]

Prints wall and CPU seconds (CPU: the children's user + system time), the
number of compiled kernel specialisations (numba cache files) and the cold
over warm ratio, and the load average.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_codegen import extract  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
BASELINE = "91de396"


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def demo(tree: Path, work: Path) -> dict:
    """``reachconf demo`` from ``tree`` with the caches below ``work`` (created empty on the first call)."""
    env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(work / "numba"),
               REACHCONF_CACHE=str(work / "models"), MPLBACKEND="Agg")  # fmt: skip
    out = work / f"out{len(list(work.glob('out*')))}"
    c0, t0 = _children_cpu(), time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "reachconf.cli", "demo", "--out", str(out)], env=env, cwd=work,
                         capture_output=True, text=True)  # fmt: skip
    wall, cpu = time.perf_counter() - t0, _children_cpu() - c0
    if res.returncode != 0:
        return {"error": (res.stderr.strip().splitlines() or [f"exit {res.returncode}"])[-1]}
    table = [line for line in res.stdout.splitlines() if line.strip().startswith("| lane_change")]
    return {"wall": wall, "cpu": cpu, "specs": len(list((work / "numba").rglob("*.nbc"))),
            "table": table[0].strip() if table else ""}  # fmt: skip


def measure(tree: Path, label: str, repeat: int) -> list:
    rows = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory(prefix="reachconf-first-") as tmp:
            work = Path(tmp)
            cold = demo(tree, work)
            warm = demo(tree, work) if "error" not in cold else cold
        rows.append((cold, warm))
        if "error" in cold:
            print(f"{label}: error: {cold['error']}", flush=True)
        else:
            print(f"{label}: cold {cold['wall']:6.1f} s wall ({cold['cpu']:6.1f} CPU), {cold['specs']} specialisations;"
                  f" warm {warm['wall']:5.1f} s; cold / warm {cold['wall'] / warm['wall']:5.1f}", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default=BASELINE, help=f"git ref of the baseline (default {BASELINE})")
    ap.add_argument("--no-baseline", action="store_true", help="only this checkout")
    ap.add_argument("--repeat", type=int, default=1, help="cold runs per tree (each with empty caches)")
    args = ap.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.2f}", flush=True)
    after = measure(REPO, "after (this checkout)", args.repeat)
    if not args.no_baseline:
        with tempfile.TemporaryDirectory(prefix="reachconf-base-") as tmp:
            before = measure(extract(args.baseline, Path(tmp)), f"before ({args.baseline})", args.repeat)
        best = {k: min(r[0]["wall"] for r in rows if "error" not in r[0]) for k, rows in
                (("after", after), ("before", before)) if any("error" not in r[0] for r in rows)}  # fmt: skip
        if len(best) == 2:
            print(f"first run, best cold wall: after / before = {best['after'] / best['before']:.2f}")
        same = {r[0].get("table") for r in after + before if "error" not in r[0]}
        print("the demo's table is the same in every run" if len(same) == 1 else f"tables differ: {sorted(same)}")
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
