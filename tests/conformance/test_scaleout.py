"""Scale-out on real worker processes: a 2-worker multi-process Dask cluster and local processes.

One ``LocalCluster(processes=True, n_workers=2)`` serves the module; its workers
have a cache folder of their own (as fresh worker machines would), so every
run here also checks that the model's compiled code reaches them.
"""

import os
import signal
import threading
import time

import numpy as np
import pytest

import reachconf as rc
from reachconf.conformance import SynthesisOptions, pareto_front, synthesize_W
from reachconf.io import TestCase, TestSuite
from reachconf.model.simulate import simulate
from reachconf.runner import Pool, WorkersLost

distributed = pytest.importorskip("dask.distributed")

V = rc.Interval([-0.01, -0.01], [0.01, 0.01])
OPTIONS = SynthesisOptions(alpha_iterations=5, merge_iterations=4)


def plant():
    return rc.Model(name="scaleout_decay", states=("x1", "x2"), disturbances=("w1", "w2"),
                    dynamics=lambda s: [-s.x1 + 0.3 * s.x2 + s.w1, -2.0 * s.x2 + 0.5 * s.x1 + s.w2])  # fmt: skip


def make_suite(model):
    cases = []
    for k in range(4):
        rng = np.random.default_rng(10 + k)
        t = np.round(np.arange(0.0, 3.0 + 1e-9, 0.05), 10)
        scale = (0.5, 1.0)[k % 2]  # two groups with different disturbance sizes
        w = (scale * rng.uniform(-1, 1, size=(t.size // 10 + 1, 2))).repeat(10, axis=0)[: t.size]
        X = simulate(model, [0.0, 0.0], t, disturbances=w, substeps=20)
        Y = X + rng.uniform(V.lo, V.hi, size=X.shape)
        cases.append(TestCase(f"c{k}", f"g{k % 2}", t, np.zeros((t.size, 0)), Y, (), model.output_names))
    return TestSuite(cases)


def same_synthesis(a, b):
    assert list(a.cases) == list(b.cases) and list(a.groups) == list(b.groups)
    for name, ca in a.cases.items():
        cb = b.cases[name]
        for box in ("W_TC", "W_opt", "W_RC"):
            np.testing.assert_array_equal(getattr(ca, box).lo, getattr(cb, box).lo)
            np.testing.assert_array_equal(getattr(ca, box).hi, getattr(cb, box).hi)
        assert ca.alpha == cb.alpha and ca.conformant == cb.conformant
    for g in a.groups:
        np.testing.assert_array_equal(a.groups[g].lo, b.groups[g].lo)
        np.testing.assert_array_equal(a.groups[g].hi, b.groups[g].hi)
        assert a.group_alpha[g] == b.group_alpha[g] and a.group_conformant[g] == b.group_conformant[g]


class KillOnce(distributed.WorkerPlugin):
    """Kill the worker process shortly after the first task of the cluster starts executing on it."""

    def __init__(self, marker):
        self.marker = marker

    def transition(self, key, start, finish, **kwargs):
        if finish != "executing":
            return
        try:
            fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return
        os.close(fd)
        threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGKILL)).start()


def close_my_worker(x):
    time.sleep(0.2)
    if x == 1:
        worker = distributed.get_worker()
        worker.loop.add_callback(worker.close)
    return x


@pytest.fixture(scope="module")
def model():
    return plant()


@pytest.fixture(scope="module")
def suite(model):
    return make_suite(model)


@pytest.fixture(scope="module")
def serial(model, suite):
    return synthesize_W(model, suite, V, OPTIONS, progress=False)


@pytest.fixture(scope="module")
def worker_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("worker-cache")


@pytest.fixture(scope="module")
def cluster(worker_cache):
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  env={"REACHCONF_CACHE": str(worker_cache)}) as cl:  # fmt: skip
        with distributed.Client(cl) as client:
            yield cl, client


def test_multi_process_cluster_gives_the_serial_results(model, suite, serial, cluster, worker_cache):
    cl, client = cluster
    res = synthesize_W(model, suite, V, OPTIONS, scheduler=cl.scheduler_address, progress=False)
    same_synthesis(serial, res)
    assert res.log == [] and set(res.groups) == {"g0", "g1"}
    # the workers did not build the model: its generated module and numba caches were installed in their cache
    files = {p.name for p in (worker_cache / "models").glob("reachconf_gen_scaleout_decay_*")}
    assert any(f.endswith(".py") for f in files) and any(f.endswith(".npz") for f in files)
    assert any(p.suffix == ".nbi" for p in (worker_cache / "models" / "__pycache__").glob("reachconf_gen_scaleout*"))

    def loaded_from_cache():
        from reachconf.model.recipe import built_models

        return [m.compiled().loaded_from_cache for m in built_models().values() if m.name == "scaleout_decay"]

    assert all(v == [True] for v in client.run(loaded_from_cache).values())


def test_one_pool_serves_synthesis_and_pareto(model, suite, serial, cluster, monkeypatch):
    import reachconf.runner.dask as rdask

    cl, _ = cluster
    connects = []
    real = rdask.connect
    monkeypatch.setattr(rdask, "connect", lambda *a, **k: connects.append(a) or real(*a, **k))
    front_serial = pareto_front(model, suite.select(names=["c1"]), V, serial.groups["g1"], iterations=3)
    with Pool(scheduler=cl.scheduler_address) as pool:
        again = synthesize_W(model, suite, V, OPTIONS, pool=pool, progress=False)
        front = pareto_front(model, suite.select(names=["c1"]), V, serial.groups["g1"], iterations=3, pool=pool)
    assert len(connects) == 1  # one client for the whole run
    same_synthesis(serial, again)
    assert [b.to_list() for b in front.boxes] == [b.to_list() for b in front_serial.boxes]
    assert front.orders == front_serial.orders


def test_pareto_on_local_processes_starts_one_pool(model, suite, serial, monkeypatch):
    import reachconf.runner.local as rlocal

    started = []
    real = rlocal.ProcessPoolExecutor
    monkeypatch.setattr(rlocal, "ProcessPoolExecutor", lambda *a, **k: started.append(1) or real(*a, **k))
    args = (model, suite.select(names=["c0", "c2"]), V, serial.groups["g0"])
    front = pareto_front(*args, iterations=3, workers=2, progress=False)
    assert started == [1]
    assert [b.to_list() for b in front.boxes] == [b.to_list() for b in pareto_front(*args, iterations=3).boxes]


def test_a_worker_killed_mid_run_is_reported_and_changes_nothing(model, suite, serial, cluster, tmp_path, capsys):
    cl, client = cluster
    marker = str(tmp_path / "killed")
    client.register_plugin(KillOnce(marker), name="kill-once")
    try:
        res = synthesize_W(model, suite, V, OPTIONS, scheduler=client, progress=False)
    finally:
        client.unregister_worker_plugin("kill-once")
        client.wait_for_workers(2, timeout=60)
    assert os.path.exists(marker)
    same_synthesis(serial, res)
    err = capsys.readouterr().err
    assert "reachconf: warning: Dask worker" in err and " lost" in err
    assert any("lost" in line for line in res.log)


def test_no_worker_left_fails_after_the_timeout_and_keeps_the_finished_results(capsys):
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl:
        with distributed.Client(cl) as client, Pool(scheduler=client, worker_timeout=1.5) as pool:
            t0 = time.perf_counter()
            with pytest.raises(WorkersLost, match="no Dask worker .* for 1.5 s") as info:
                pool.map(close_my_worker, range(6), progress=False)
            assert time.perf_counter() - t0 < 30
    assert info.value.partial[0] == 0 and info.value.partial[-1] is None
    assert "no Dask worker left" in capsys.readouterr().err
