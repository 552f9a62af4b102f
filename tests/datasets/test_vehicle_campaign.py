"""Vehicle campaign: smooth references, deterministic multi-body runs, switchable effects."""

import numpy as np
import pytest

from reachconf.datasets.vehicle_campaign import NO_EFFECTS, PlantEffects, make_case, reference_path

pytest.importorskip("vehiclemodels")


@pytest.mark.parametrize("kind", ["LC", "SW", "DLC", "SL"])
@pytest.mark.parametrize("a_lat", [2.0, 4.0])
def test_reference_is_smooth_and_scaled(kind, a_lat):
    r = reference_path(kind, a_lat, 10.0)
    peak = np.max(np.abs(r["v_ref"] ** 2 * r["kappa_ref"]))
    assert abs(peak - a_lat) < 0.03 * a_lat
    # no kinks: heading and curvature change by small amounts between 100 Hz samples
    assert np.max(np.abs(np.diff(r["psi_ref"]))) < 0.01
    assert np.max(np.abs(np.diff(r["kappa_ref"]))) < 0.002
    speed = np.hypot(np.gradient(r["X_ref"], r["t"]), np.gradient(r["Y_ref"], r["t"]))
    assert np.allclose(speed, 10.0, rtol=1e-3)


def test_campaign_case_is_deterministic_and_tracks():
    a = make_case("LC", 2.0, 0, seed=3)
    b = make_case("LC", 2.0, 0, seed=3)
    c = make_case("LC", 2.0, 1, seed=3)
    np.testing.assert_array_equal(a.Y, b.Y)
    assert not np.array_equal(a.Y, c.Y)  # repetitions differ in their noise
    assert a.group == "LC_2" and a.input_names == ("ax", "delta")
    assert {"ax_req", "delta_req", "X_ref", "kappa_ref"} <= set(a.extras)
    lat = -(a.signal("X") - a.signal("X_ref")) * np.sin(a.signal("psi_ref")) + (
        a.signal("Y") - a.signal("Y_ref")
    ) * np.cos(a.signal("psi_ref"))
    assert np.max(np.abs(lat)) < 0.3


def test_effects_switch_off():
    ideal = make_case("LC", 2.0, 0, effects=NO_EFFECTS)
    # ideal actuators: realised acceleration = request; no noise, no offsets
    np.testing.assert_allclose(ideal.signal("ax")[1:], ideal.signal("ax_req")[1:], atol=1e-9)
    lagged = make_case("LC", 2.0, 0, effects=PlantEffects().without("noise", "offsets", "delays", "scales"))
    d_err = np.abs(lagged.signal("delta")[1:] - lagged.signal("delta_req")[1:])
    assert d_err.max() > 1e-3  # the steering lag shows between request and realised angle
    with pytest.raises(ValueError, match="unknown effect"):
        PlantEffects().without("gremlins")


def test_campaign_on_a_pool_is_the_serial_campaign():
    from reachconf.datasets.vehicle_campaign import make_campaign
    from reachconf.runner import Pool

    kw = dict(maneuvers=("LC",), accelerations=(2.0,), repetitions=2, seed=5, progress=False)
    serial = make_campaign(**kw)
    with Pool(2) as pool:
        pooled = make_campaign(pool=pool, **kw)
    assert [c.name for c in pooled] == [c.name for c in serial] == ["LC_2_1", "LC_2_2"]
    for a, b in zip(serial, pooled):
        np.testing.assert_array_equal(a.Y, b.Y)
        np.testing.assert_array_equal(a.U, b.U)
        assert a.extras.keys() == b.extras.keys()
    from reachconf.errors import OptionsError

    with pytest.raises(OptionsError, match="pool must be a reachconf.runner.Pool"):
        make_campaign(pool=2, **kw)
