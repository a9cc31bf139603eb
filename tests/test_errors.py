"""The one unknown-key helper every configuration section uses; exit codes of the error types
and the one-line OS-fault message."""

import pytest

from gravsurvey.errors import ConfigError, check_keys, suggest


def test_suggest_prefers_a_case_match_then_the_closest_name():
    assert suggest("MGAL", ["g", "mGal", "m/s^2"]) == " (did you mean 'mGal'?)"
    assert suggest("speeed", ["speed_mps", "height_m"]) == " (did you mean 'speed_mps'?)"
    assert suggest("colour", ["speed_mps", "height_m"]) == ""
    assert suggest(7, [1, 2, 3.5]) == ""  # non-strings are compared as text
    assert suggest(3, [1, 2, 3.5]) == " (did you mean '3.5'?)"
    # another spelling of a unit (fuzzing, 2026-12-04: "dps" was answered with 'rad/s')
    gyro = ["rad/s", "deg/s", "deg/h", "rad", "deg"]
    assert suggest("dps", gyro) == " (did you mean 'deg/s'?)"
    assert suggest("DPH", gyro) == " (did you mean 'deg/h'?)"
    assert suggest("feet", ["m", "ft"]) == " (did you mean 'ft'?)"
    assert suggest("dps", ["m", "ft"]) == ""  # a spelling of a unit not among the choices


def test_check_keys_names_the_key_path_and_the_valid_keys():
    check_keys({"a": 1}, ("a", "b"), "x")
    with pytest.raises(ConfigError, match=r"^x\.y\.bb: unknown key \(did you mean 'b'\?\); valid keys here: a, b$"):
        check_keys({"a": 1, "bb": 2}, ("a", "b"), "x.y")
    with pytest.raises(ConfigError, match=r"^zzz: unknown key; valid keys here: a, b$"):
        check_keys({"zzz": 1}, ("a", "b"), "")
    with pytest.raises(ConfigError, match=r"^x\.b: missing required key$"):
        check_keys({"a": 1}, ("a", "b"), "x", required=("a", "b"))


def test_each_error_type_has_its_documented_exit_code():
    import errno

    from gravsurvey.errors import (
        EXIT_CODES,
        DataError,
        EnvironmentFault,
        GravsurveyError,
        RegressionFailure,
        os_fault,
    )

    got = {t.__name__: t.exit_code for t in (DataError, ConfigError, EnvironmentFault, RegressionFailure)}
    assert got == {"DataError": 1, "ConfigError": 2, "EnvironmentFault": 3, "RegressionFailure": 4}
    assert all(issubclass(t, GravsurveyError) for t in (DataError, ConfigError, EnvironmentFault))
    assert set(got.values()) <= set(EXIT_CODES)
    f = os_fault(OSError(errno.ENOSPC, "No space left on device", "out/profiles.csv"), "write")
    assert isinstance(f, EnvironmentFault) and f.exit_code == 3
    assert str(f) == "out/profiles.csv: cannot write: No space left on device"
    f = os_fault(OSError(errno.EXDEV, "Invalid cross-device link", "a/.staging", None, "a/out"))
    assert str(f) == "a/.staging -> a/out: Invalid cross-device link"
    assert str(os_fault(OSError(errno.EACCES, None))) == "?: Permission denied"
