"""gravsurvey's own exception types.

The CLI catches :class:`GravsurveyError` once and turns it into an exit code
and a one-line message: 1 for data problems, 2 for usage/config problems.
"""


class GravsurveyError(Exception):
    """Base class. ``exit_code`` is what the CLI returns."""

    exit_code = 1


class DataError(GravsurveyError):
    """Input data are missing, damaged or implausible (exit code 1)."""

    exit_code = 1


class ConfigError(GravsurveyError):
    """A configuration file or command line is invalid (exit code 2)."""

    exit_code = 2


class DataWarning(UserWarning):
    """Something in the data was repaired or looks suspicious; processing continues."""
