"""reachconf's computations run with one OpenBLAS thread, and the caller's setting comes back afterwards."""

import numpy as np
import pytest
import scipy.linalg  # noqa: F401 - loads scipy's OpenBLAS too

from reachconf import blas_threads as bt


def _threads():
    return [bt._control(p)[0]() for p in bt._loaded_openblas() if bt._control(p)]


@pytest.fixture
def two_threads():
    libs = [bt._control(p) for p in bt._loaded_openblas() if bt._control(p)]
    if not libs:
        pytest.skip("no OpenBLAS library with a thread setter loaded (not Linux, or another BLAS)")
    before = [get() for get, _ in libs]
    for _, set_ in libs:
        set_(2)
    yield
    for (_, set_), n in zip(libs, before):
        set_(n)


def test_one_thread_inside_restored_after_and_nested(two_threads):
    assert set(_threads()) == {2}
    with bt.one_blas_thread():
        assert set(_threads()) == {1}
        with bt.one_blas_thread():
            assert set(_threads()) == {1}
        assert set(_threads()) == {1}  # the inner block does not restore while the outer one runs
        np.ones((300, 300)) @ np.ones((300, 300))  # BLAS still works
    assert set(_threads()) == {2}


def test_restored_when_the_block_raises(two_threads):
    with pytest.raises(ZeroDivisionError):
        with bt.one_blas_thread():
            assert set(_threads()) == {1}
            1 / 0
    assert set(_threads()) == {2}


def test_diagnose_runs_with_one_thread(two_threads, monkeypatch):
    import reachconf as rc
    from reachconf.diagnose import pipeline

    seen = []

    def fake_prepare(*args, **kwargs):
        seen.append(_threads())
        raise RuntimeError("stop here")

    monkeypatch.setattr(pipeline, "prepare", fake_prepare)
    t = np.linspace(0.0, 1.0, 11)
    model = rc.models.bicycle()
    cases = [rc.TestCase(f"c{i}", "g", t, np.zeros((11, model.m)), np.zeros((11, model.p)),
                          model.input_names, model.output_names) for i in range(2)]  # fmt: skip
    with pytest.raises(RuntimeError, match="stop here"):
        rc.diagnose(model, cases, progress=False)
    assert seen and set(seen[0]) == {1}
    assert set(_threads()) == {2}
