"""The diagnosis's fits and traces on forked processes: the same report as in one process, and safe fallbacks."""

import json
import multiprocessing as mp
import pickle
import sys

import numpy as np
import pytest

import reachconf as rc
from reachconf.diagnose import EFFECTS
from reachconf.diagnose.effects import Effect
from reachconf.diagnose.parallel import FitMap, auto_workers, picklable
from reachconf.errors import OptionsError

from test_diagnose import _oscillator_suite

fork_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fit workers are forked on Linux only")


def _auto_in_child(q):
    q.put(auto_workers())


def test_registered_effects_travel_by_name_and_others_by_value():
    for e in EFFECTS.values():
        assert pickle.loads(pickle.dumps(e)) is e
    lam = Effect("my_offset", "input", ("c",), lambda x: (0.0,), lambda x: ((-1.0,), (1.0,)),
                 signal=lambda t, u, th: u + th[0])  # fmt: skip
    assert not lam.registered and not picklable([lam])
    assert picklable(list(EFFECTS.values()))


@fork_only
def test_fit_map_keeps_job_order_and_reports_each_result():
    seen = []
    out = FitMap(2)([lambda i=i: i * i for i in range(7)], done=lambda i, r: seen.append((i, r)))
    assert out == [i * i for i in range(7)]
    assert seen == list(enumerate(out))
    assert FitMap(1)([lambda: 3]) == [3]
    with pytest.raises(OptionsError, match="workers"):
        FitMap(0)


@fork_only
def test_auto_workers_is_one_inside_a_worker_process():
    assert auto_workers() >= 1
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_auto_in_child, args=(q,))
    p.start()
    p.join(60)
    assert q.get(timeout=5) == 1


@fork_only
def test_diagnosis_on_two_processes_equals_the_one_process_report():
    m, suite = _oscillator_suite(lag=0.1, n=4)
    one = rc.diagnose(m, suite, progress=False, workers=1)
    two = rc.diagnose(m, suite, progress=False, workers=2)
    assert one.base["workers"] == 1 and two.base["workers"] == 2
    assert json.dumps(one.decision, sort_keys=True, default=str) == json.dumps(two.decision, sort_keys=True,
                                                                               default=str)  # fmt: skip
    assert [e["label"] for e in one.ranked_effects] == [e["label"] for e in two.ranked_effects]
    for a, b in zip(one.ranked_effects, two.ranked_effects):
        assert json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)
    assert one.verdict == two.verdict and "actuator_lag" in one.verdict
    # where, how far and the model-free check (the traces and the two boxes run on the workers too)
    for part in ("where", "before_after", "features"):
        assert json.dumps(getattr(one, part), sort_keys=True, default=str) == json.dumps(
            getattr(two, part), sort_keys=True, default=str), part  # fmt: skip
    assert one.before_after["W"] and one.where["location"]["shares"]
    for x, y in zip([one.scores["base"]] + [s["losses"] for s in one.scores["models"]],
                    [two.scores["base"]] + [s["losses"] for s in two.scores["models"]]):  # fmt: skip
        np.testing.assert_array_equal(x, y)
    # an effect that cannot travel (lambdas, not registered) keeps the fits in this process
    lam = Effect("my_offset", "input", ("c",), lambda x: (0.0,), lambda x: ((-1.0,), (1.0,)),
                 signal=lambda t, u, th: u + th[0])  # fmt: skip
    rep = rc.diagnose(m, suite, effects=[lam, "actuator_lag"], progress=False, workers=2)
    assert rep.base["workers"] == 1 and "actuator_lag" in rep.verdict


@fork_only
def test_reachset_W_of_both_models_on_two_processes_equals_one_process():
    """With ``reach=True`` the synthesis of each model's W runs in its own worker (it starts its own pool there)."""
    m, suite = _oscillator_suite(lag=0.2, n=4, seed=5)
    reps = [rc.diagnose(m, suite, effects=["actuator_lag"], progress=False, reach=True, workers=w) for w in (1, 2)]
    assert reps[1].base["workers"] == 2
    assert reps[0].before_after["W_reachset_conformant"] == {"before": True, "after": True}
    assert json.dumps(reps[0].before_after, sort_keys=True, default=str) == json.dumps(
        reps[1].before_after, sort_keys=True, default=str)  # fmt: skip


def _dies_in_a_worker(value):
    import os

    from reachconf.diagnose import parallel

    if parallel._IN_WORKER and value == 2:
        os._exit(9)  # as if killed
    return value


@fork_only
def test_a_dead_worker_loses_nothing():
    with pytest.warns(RuntimeWarning, match="worker process died"):
        out = FitMap(2)([lambda v=v: _dies_in_a_worker(v) for v in range(5)])
    assert out == list(range(5))


@fork_only
def test_stages_of_concurrent_threads_do_not_mix():
    import threading

    results = {}

    def run(tag):
        results[tag] = FitMap(2)([lambda v=v: (tag, v) for v in range(6)])

    threads = [threading.Thread(target=run, args=(t,)) for t in "ab"]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert results == {t: [(t, v) for v in range(6)] for t in "ab"}


def test_bad_workers_are_named_errors_before_any_work(monkeypatch):
    m, suite = _oscillator_suite(lag=0.1, n=2)
    lam = Effect("my_offset", "input", ("c",), lambda x: (0.0,), lambda x: ((-1.0,), (1.0,)),
                 signal=lambda t, u, th: u + th[0])  # fmt: skip
    for bad in (0, -2, 1.5, True, "two"):
        with pytest.raises(OptionsError, match="workers"):
            rc.diagnose(m, suite, progress=False, workers=bad)
        with pytest.raises(OptionsError, match="workers"):  # also where the effects keep the fits in this process
            rc.diagnose(m, suite, effects=[lam], progress=False, workers=bad)
    if sys.platform.startswith("linux"):  # (read only where the fits are forked)
        for text in ("0", "abc", "1.5"):
            monkeypatch.setenv("REACHCONF_DIAGNOSE_WORKERS", text)
            with pytest.raises(OptionsError, match="REACHCONF_DIAGNOSE_WORKERS"):
                rc.diagnose(m, suite, progress=False)
