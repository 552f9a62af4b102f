"""``reachconf conform`` and ``reachconf reach`` on the run's pool (``--workers``, ``--scheduler``, ``--worker-timeout``)."""

import json
import shutil

import numpy as np
import pytest

from reachconf import cli
from reachconf.demo import demo_run_file
from reachconf.runner import Pool, WorkersLost


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    dst = tmp_path_factory.mktemp("cases") / "demo"
    shutil.copytree(demo_run_file().parent, dst)
    return dst / "run.toml"


@pytest.fixture(autouse=True)
def restore_timeout_variable(monkeypatch):
    # --worker-timeout sets REACHCONF_WORKER_TIMEOUT in this process; monkeypatch puts the old state back
    monkeypatch.setenv("REACHCONF_WORKER_TIMEOUT", "60")


def main(capsys, *argv):
    status = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err.strip().splitlines()


def without_seconds(results):
    return {case: {kind: {k: v for k, v in e.items() if k != "seconds"} for kind, e in entry.items()}
            for case, entry in results.items()}  # fmt: skip


@pytest.fixture(scope="module")
def serial_conformance(run_file, tmp_path_factory):
    target = tmp_path_factory.mktemp("serial") / "c.json"
    assert cli.main(["conform", str(run_file), "--json", str(target)]) == 0
    return json.loads(target.read_text())


def test_conform_on_two_workers_gives_the_serial_verdicts(run_file, serial_conformance, tmp_path, capsys):
    status, out, _ = main(capsys, "conform", run_file, "--json", tmp_path / "c.json", "--workers", 2,
                          "--worker-timeout", 30)  # fmt: skip
    assert status == 0 and "workers: 2 local processes" in out
    parallel = json.loads((tmp_path / "c.json").read_text())
    assert list(parallel) == list(serial_conformance) == ["lane_change_01", "lane_change_02", "lane_change_03"]
    assert without_seconds(parallel) == without_seconds(serial_conformance)
    assert all(e["trace"]["conformant"] is True and e["reachset"]["conformant"] is True for e in parallel.values())


def test_reach_on_two_workers_gives_the_serial_tubes(run_file, tmp_path, capsys):
    assert main(capsys, "reach", run_file, "--json", tmp_path / "s.json")[0] == 0
    status, out, _ = main(capsys, "reach", run_file, "--json", tmp_path / "p.json", "--out", tmp_path / "p",
                          "--workers", 2)  # fmt: skip
    assert status == 0
    serial, parallel = (json.loads((tmp_path / f"{n}.json").read_text()) for n in "sp")
    assert list(serial) == list(parallel)
    for name in serial:
        np.testing.assert_array_equal(np.asarray(serial[name]["bounds"]), np.asarray(parallel[name]["bounds"]))
        assert (tmp_path / "p" / f"{name}_tube.npz").is_file() and (tmp_path / "p" / f"{name}_tube.png").is_file()


def test_conform_on_a_multi_process_dask_cluster_gives_the_serial_verdicts(run_file, serial_conformance, tmp_path,
                                                                           capsys):  # fmt: skip
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  env={"REACHCONF_CACHE": str(tmp_path / "worker-cache")}) as cluster:  # fmt: skip
        status, out, _ = main(capsys, "conform", run_file, "--kind", "trace", "--json", tmp_path / "d.json",
                              "--scheduler", cluster.scheduler_address)  # fmt: skip
    assert status == 0 and "Dask cluster" in out
    dask = json.loads((tmp_path / "d.json").read_text())
    trace_only = {case: {"trace": entry["trace"]} for case, entry in serial_conformance.items()}
    assert without_seconds(dask) == without_seconds(trace_only)


def test_lost_workers_keep_the_finished_cases_by_name(run_file, tmp_path, capsys, monkeypatch):
    from reachconf.cli_cases import conform_case

    def lose_after_first(self, fn, jobs, **kwargs):
        first = conform_case(jobs[0])
        raise WorkersLost("no worker left for 30 s (2 of 3 jobs unfinished)", partial=[first, None, None])

    monkeypatch.setattr(Pool, "map", lose_after_first)
    status, _, err = main(capsys, "conform", run_file, "--kind", "trace", "--json", tmp_path / "c.json",
                          "--workers", 2)  # fmt: skip
    assert status == cli.EXIT_WORKERS_LOST and len(err) == 1 and "partial results in" in err[0], err
    saved = json.loads((tmp_path / "c.partial.json").read_text())
    assert saved["complete"] is False and list(saved["partial"]) == ["lane_change_01"]
    assert saved["partial"]["lane_change_01"]["trace"]["conformant"] is True
    assert not (tmp_path / "c.json").exists()


def test_worker_timeout_reaches_every_pool_of_the_command(run_file, tmp_path, capsys, monkeypatch):
    seen = []

    def record(self, fn, jobs, **kwargs):
        seen.append(self.worker_timeout)
        return [fn(job) for job in jobs]

    monkeypatch.setattr(Pool, "map", record)
    status, _, _ = main(capsys, "conform", run_file, "--kind", "trace", "--workers", 2, "--worker-timeout", 7.5)
    assert status == 0 and seen == [7.5]


@pytest.mark.parametrize("argv, needle", [
    (("conform", "RUN", "--worker-timeout", "-1"), "positive, finite number of seconds"),
    (("conform", "RUN", "--worker-timeout", "nan"), "positive, finite number of seconds"),
    (("reach", "RUN", "--worker-timeout", "soon"), "must be a number of seconds"),
    (("conform", "RUN", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"), "cannot connect"),
    (("diagnose", "RUN", "--scheduler", "tcp://127.0.0.1:1"), "unrecognized arguments: --scheduler"),
    (("diagnose", "RUN", "--workers", "0"), "must be a positive integer, got 0"),
])  # fmt: skip
def test_bad_pool_options_are_one_line_errors(run_file, capsys, argv, needle):
    status, out, err = main(capsys, *[str(run_file) if a == "RUN" else a for a in argv])
    assert status == 2 and len(err) == 1 and needle in err[0], err
    assert "conformant" not in out
