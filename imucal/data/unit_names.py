"""Unit spellings that files use (CF/UDUNITS and common ones), for every reader: a netCDF variable's units
attribute (imucal.data.netcdf) and a unit in a text header's names (imucal.data.header_names).

Each table maps a spelling (lower case) to (our unit, factor, offset): value in our unit = factor x value + offset.
"""
from __future__ import annotations

from imucal.mag.units import FIELD_UNITS as FIELD_UT  # each field unit in microtesla: the factors, once

ACCELERATION_UNITS = {u: ("m/s^2", 1.0, 0.0) for u in (
    "m/s2", "m/s^2", "m/s**2", "m s-2", "m.s-2", "m s^-2", "meter/second2", "meters per second squared", "m/s²",
    "m/s/s")}
ACCELERATION_UNITS.update({u: ("g", 1.0, 0.0) for u in ("g", "g0", "gn", "g_n")})
RATE_UNITS = {**{u: ("rad/s", 1.0, 0.0) for u in ("rad/s", "rad s-1", "rad.s-1", "radian/second", "radians/s",
                                                   "rad s^-1", "rad/sec")},
              **{u: ("rad/s", 1e-3, 0.0) for u in ("mrad/s", "mrad s-1", "mrad.s-1", "milliradian/second")},
              **{u: ("deg/s", 1.0, 0.0) for u in ("deg/s", "deg s-1", "degree/s", "degrees/s", "dps",
                                                  "degree/second", "degrees per second", "deg s^-1", "deg/sec",
                                                  "°/s")}}
TEMPERATURE_UNITS = {**{u: ("degC", 1.0, 0.0) for u in ("c", "degc", "deg c", "deg_c", "celsius", "degree_celsius",
                                                        "degrees_celsius", "degrees celsius", "°c", "degree_c",
                                                        "degrees_c", "degree c", "degrees c", "deg. c", "℃")},
                     **{u: ("degC", 1.0, -273.15) for u in ("k", "kelvin", "degk", "degrees_kelvin", "degree_kelvin",
                                                            "degree_k", "degrees_k")},
                     **{u: ("degC", 5.0 / 9.0, -32.0 * 5.0 / 9.0) for u in ("f", "degf", "fahrenheit", "degree_f",
                                                                            "degrees_fahrenheit", "degree_fahrenheit",
                                                                            "degrees_f", "°f")}}
#: Magnetic field (a magnetometer mapped by data.columns mx: VARIABLE): kept in its unit (imucal.mag.units.FIELD_UNITS),
#: tesla and millitesla in microtesla.
FIELD_UNITS = {**{u: ("uT", 1.0, 0.0) for u in ("ut", "microtesla", "micro tesla", "µt", "μt", "micro_tesla")},
               **{u: ("nT", 1.0, 0.0) for u in ("nt", "nanotesla", "nano tesla", "nano_tesla")},
               **{u: ("uT", FIELD_UT["mT"], 0.0) for u in ("mt", "millitesla")},
               **{u: ("uT", FIELD_UT["T"], 0.0) for u in ("t", "tesla")},
               **{u: ("gauss", 1.0, 0.0) for u in ("gauss", "gs")},  # not "g" nor "mg": an acceleration's
               **{u: ("mG", 1.0, 0.0) for u in ("milligauss", "mgauss")}}
#: The units of each kind, in words (messages).
KNOWN_UNITS = {"acceleration": "m/s^2 (m/s2, m s-2) or g", "angular rate": "rad/s, mrad/s or deg/s",
               "temperature": "degC (C, celsius), K or degF", "magnetic field": "uT, nT, mT, T, gauss or milligauss"}
