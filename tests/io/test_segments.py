"""TestCase.segments / TestSuite.segments: consecutive stretches of a case (section 4.3.3's shorter horizons)."""

import numpy as np
import pytest

import reachconf as rc
from reachconf.io import TestCase, TestSuite


def _case(duration=8.39, dt=0.01, name="run", group="G", t0=0.0):
    t = t0 + dt * np.arange(int(round(duration / dt)) + 1)
    return TestCase.from_signals(name, t, {"u": np.sin(t), "y": np.cos(t), "extra": t**2}, ("u",), ("y",), group)


@pytest.mark.parametrize("length", [0.5, 1.0, 2.0, 2.37, 8.0])
@pytest.mark.parametrize("t0", [0.0, 13.456])
def test_segments_cover_every_sample_and_share_boundaries(length, t0):
    case = _case(t0=t0)
    segs = case.segments(length)
    assert len(segs) == int(np.ceil(case.duration / length - 1e-9))
    joined = np.concatenate([s.t for s in segs])
    assert np.array_equal(np.unique(joined), case.t)  # every sample in a segment
    for a, b in zip(segs[:-1], segs[1:]):
        assert a.t[-1] == b.t[0]  # consecutive segments share their boundary sample
        assert a.duration == pytest.approx(length, abs=0.011)
    for s in segs:
        label = [np.format_float_positional(x, precision=6, unique=False, trim="-") for x in (s.t[0], s.t[-1])]
        assert s.group == "G" and s.name == f"run[{label[0]},{label[1]}]"
        i = int(np.searchsorted(case.t, s.t[0]))
        k = s.t.size
        assert np.array_equal(s.U, case.U[i:i + k]) and np.array_equal(s.Y, case.Y[i:i + k])
        assert np.array_equal(s.extras["extra"], case.extras["extra"][i:i + k])
    assert segs[-1].t[-1] == case.t[-1]


def test_partial_false_drops_the_short_tail():
    case = _case()
    full = case.segments(2.0, partial=False)
    assert [s.name for s in full] == ["run[0,2]", "run[2,4]", "run[4,6]", "run[6,8]"]
    assert case.segments(2.0)[-1].name == "run[8,8.39]"
    assert len(_case(duration=8.0).segments(2.0, partial=False)) == 4  # no tail: nothing dropped


def test_a_short_case_is_its_own_segment_and_suites_segment_every_case():
    case = _case(duration=1.5)
    assert case.segments(2.0) == [case] and case.segments(2.0, partial=False) == []
    whole = _case(duration=2.0)
    assert whole.segments(2.0, partial=False) == [whole]  # exactly one length: kept
    with pytest.raises(rc.DataError, match="every case is shorter than the segment length"):
        TestSuite([case], name="S").segments(2.0, partial=False)
    suite = TestSuite([_case(name="a"), _case(duration=3.0, name="b", group="H")], name="S")
    segs = suite.segments(2.0)
    assert isinstance(segs, TestSuite) and segs.name == "S"
    assert [c.name for c in segs] == ["a[0,2]", "a[2,4]", "a[4,6]", "a[6,8]", "a[8,8.39]", "b[0,2]", "b[2,3]"]
    assert set(segs.groups()) == {"G", "H"}


def test_segment_names_keep_their_times_apart_on_large_time_stamps():
    """Unix-time stamps: names to the microsecond, so segments shorter than a second still get distinct names."""
    case = _case(duration=3.0, dt=0.05, t0=1_700_000_000.0)
    names = [s.name for s in case.segments(0.25)]
    assert len(set(names)) == len(names) == 12
    assert names[:2] == ["run[1700000000,1700000000.25]", "run[1700000000.25,1700000000.5]"]


def test_sliding_segments_overlap_by_length_minus_step():
    case = _case()
    segs = case.segments(2.0, step=0.5)
    starts = [s.t[0] for s in segs]
    assert np.allclose(starts, 0.5 * np.arange(14))  # 13 full windows (starts 0..6) and the tail from 6.5
    assert all(s.duration == pytest.approx(2.0) for s in segs[:-1]) and segs[-1].name == "run[6.5,8.39]"
    assert len({s.name for s in segs}) == len(segs)
    assert len(case.segments(2.0, partial=False, step=0.5)) == 13
    assert [s.name for s in case.segments(2.0, step=2.0)] == [s.name for s in case.segments(2.0)]
    with pytest.raises(rc.DataError, match="segment step 3 s is longer than the segments"):
        case.segments(2.0, step=3.0)
    with pytest.raises(rc.DataError, match="segment step must be a positive number"):
        case.segments(2.0, step=0)


def test_a_gap_in_the_sampling_longer_than_a_segment_is_skipped_not_the_rest():
    t = np.concatenate([np.arange(0, 2.001, 0.1), np.arange(5.0, 7.001, 0.1)])
    case = TestCase.from_signals("gap", t, {"u": t, "y": t}, ("u",), ("y",))
    segs = case.segments(1.0)
    covered = np.unique(np.concatenate([s.t for s in segs]))
    assert covered.size == t.size and segs[-1].t[-1] == pytest.approx(7.0)


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "two", None])
def test_bad_lengths_are_data_errors_naming_the_case(bad):
    with pytest.raises(rc.DataError, match="test case 'run': segment length"):
        _case().segments(bad)


def test_segments_are_checked_from_their_own_first_sample():
    """A reach over a segment starts at the segment's measured first sample (eq. 67), not at the case's."""
    from reachconf.conformance.reachset import initial_set
    from reachconf.demo import demo_run_file
    from reachconf.io import load_suite

    model = rc.models.bicycle_closed_loop()
    case = load_suite(demo_run_file().parent / "suite", model=model)[0]
    V = rc.Interval(-0.01 * np.ones(model.p), 0.01 * np.ones(model.p))
    second = case.segments(1.0)[1]
    X0 = initial_set(model, second, V)
    assert np.allclose(X0.center, second.Y[0, : model.n]) and not np.allclose(X0.center, case.Y[0, : model.n])
