"""Long recordings in bounded memory: a 100,000-sample case (1,000 s at 100 Hz) through the command line."""

import json
import subprocess
import sys

import pytest

from reachconf.demo import make_long_case
from reachconf.io import TestSuite, save_suite

SCRIPT = """
import json, resource, sys
from reachconf.cli import main
code = main(["conform", sys.argv[1], "--kind", "both", "--json", sys.argv[2]])
print(json.dumps({"exit": code, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


@pytest.mark.slow
def test_100k_samples_conform_in_under_500_MB(tmp_path, repo_root):
    """Trace (Alg. 2 in windows) and reachset conformance (streamed reach) of 10^5 samples: peak RSS < 500 MB.

    About 2 min on 2 cores.  The process's peak resident memory includes the
    interpreter, numpy/scipy/numba and the compiled model (about 230 MB).
    """
    case = make_long_case(100_000, maneuver="straight", seed=11)
    save_suite(TestSuite([case]), tmp_path / "suite")
    demo = (repo_root / "reachconf" / "data" / "demo" / "run.toml").read_text()
    (tmp_path / "run.toml").write_text(demo)
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / "run.toml"), str(tmp_path / "v.json")],
                         capture_output=True, text=True, timeout=1800)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    info = json.loads(out.stdout.strip().splitlines()[-1])
    verdicts = json.loads((tmp_path / "v.json").read_text())[case.name]
    assert info["exit"] == 0
    assert verdicts["trace"]["conformant"], verdicts["trace"]["message"]
    assert verdicts["reachset"]["conformant"], verdicts["reachset"]["message"]
    assert "DISTURBANCETRACE" in out.stderr and "reach bicycle_closed_loop" in out.stderr  # progress was shown
    assert info["peak_mb"] < 500, info
