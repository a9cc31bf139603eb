"""The one UTC formatter (gravsurvey.utc) against the standard library's datetime."""

import datetime as dt

import numpy as np
import pytest

from gravsurvey.utc import utc_iso, utc_iso_array


def _reference(ns: int, digits: int) -> str:
    s, frac = divmod(ns, 10**9)
    d = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc) + dt.timedelta(seconds=s)
    text = d.strftime("%Y-%m-%dT%H:%M:%S")
    return text + (f".{frac:09d}"[: digits + 1] if digits else "") + "Z"


@pytest.mark.parametrize("digits", [0, 1, 3, 6, 9])
def test_utc_iso_matches_datetime_truncated(digits):
    rng = np.random.default_rng(5)
    stamps = [0, 1, 10**9 - 1, -1, -(10**9) - 1, 1714557600_125_999_999]
    stamps += [int(v) for v in rng.integers(-(2**62), 2**62, 200)]
    for ns in stamps:
        assert utc_iso(ns, digits) == _reference(ns, digits), ns


def test_utc_iso_prints_a_stamp_out_of_range_and_refuses_bad_digits():
    assert utc_iso(2**70) == f"{2**70} ns"
    with pytest.raises(ValueError, match="digits"):
        utc_iso(0, 10)


def test_utc_iso_array_rounds_half_up_to_milliseconds():
    ns = np.array([1714557600_124_499_999, 1714557600_124_500_000, -500_000, 0])
    assert utc_iso_array(ns).tolist() == [
        "2024-05-01T10:00:00.124Z",
        "2024-05-01T10:00:00.125Z",
        "1970-01-01T00:00:00.000Z",
        "1970-01-01T00:00:00.000Z",
    ]
