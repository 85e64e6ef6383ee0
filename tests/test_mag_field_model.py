"""The field model (optional extra imucal-nlp[mag]: the IGRF through ppigrf) and what it decides (issue 26)."""
from __future__ import annotations

import datetime as dt
import sys

import numpy as np
import pytest

from imucal.errors import ImucalError
from imucal.mag import field_model
from imucal.mag.calibrate import MagSettings, calibrate_mag
from imucal.mag.field_model import EarthField, Place, earth_field
from imucal.mag.simulate import MagTruth, simulate_mag


def test_igrf_at_greenwich_2020():
    """London's agonic year: declination within a degree of zero, inclination 66-67 deg, F about 49 uT."""
    import ppigrf  # noqa: F401  (the test extra)
    f = earth_field(51.48, 0.0, 0.0, dt.date(2020, 1, 1))
    assert abs(f.declination_deg) < 1.0 and 66.0 < f.inclination_deg < 67.5 and 48.0 < f.intensity_uT < 50.0
    south = earth_field(-33.9, 151.2, 0.0, dt.date(2024, 6, 1))  # Sydney: the field points up
    assert south.inclination_deg < -60 and south.dip > 0 > f.dip


def test_without_ppigrf_a_one_line_refusal(monkeypatch):
    monkeypatch.setitem(sys.modules, "ppigrf", None)
    with pytest.raises(ImucalError) as e:
        earth_field(51.48, 0.0, 0.0, dt.date(2020, 1, 1))
    assert str(e.value) == ("mag.place: the field model needs the ppigrf package (fix: pip install imucal-nlp[mag], "
                            "or give the field's magnitude (mag.field))")


@pytest.mark.parametrize("args, field", [((91.0, 0.0, 0.0, dt.date(2020, 1, 1)), "mag.place.latitude"),
                                         ((10.0, 0.0, 0.0, dt.date(1850, 1, 1)), "mag.place.date"),
                                         ((10.0, 0.0, 1e7, dt.date(2020, 1, 1)), "mag.place.height")])
def test_place_out_of_range(args, field):
    with pytest.raises(ImucalError) as e:
        earth_field(*args)
    assert str(e.value).startswith(field + ": ")


def _north(monkeypatch) -> None:
    """A place whose model field points 60 deg down (the simulation's truth): no package needed."""
    monkeypatch.setattr(field_model, "earth_field",
                        lambda *a: EarthField(50.0, 60.0, 2.0, "test"))


def test_the_model_gives_F_and_checks_handedness(monkeypatch):
    _north(monkeypatch)
    truth = MagTruth(field=0.5, noise=0.002)  # the field in gauss: 50 uT
    sim = simulate_mag(truth, n_poses=20, seed=21)
    place = Place(50.0, 8.0, dt.date(2024, 1, 1))
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, raw_unit="gauss", settings=MagSettings(place=place))
    assert cal.params["F"].fixed and cal.params["F"].value == pytest.approx(0.5) and cal.earth.model == "test"
    assert cal.left_handed is False
    mirrored = sim.mag * np.array([1.0, 1.0, -1.0])  # mz wired inverted: a left-handed magnetometer
    cal = calibrate_mag(mirrored, sim.acc, still=sim.holds, raw_unit="gauss", settings=MagSettings(place=place))
    assert cal.left_handed is True and cal.params["dip"].value > 0
