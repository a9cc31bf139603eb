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


def suggest(word, choices) -> str:
    """``" (did you mean 'x'?)"`` for the choice nearest to ``word``, or ``""``.

    A choice equal to ``word`` up to case wins; otherwise the closest by
    :func:`difflib.get_close_matches` with a similarity of at least 0.5.
    """
    import difflib

    names = [str(c) for c in choices]
    same = [c for c in names if c.lower() == str(word).lower()]
    near = same or difflib.get_close_matches(str(word), names, n=1, cutoff=0.5)
    return f" (did you mean {near[0]!r}?)" if near else ""


def check_keys(d, valid, path: str, required=()) -> None:
    """Reject the first key of mapping ``d`` that is not in ``valid``, then any missing ``required``.

    Messages (one format for every configuration section)::

        <path>.<key>: unknown key (did you mean 'x'?); valid keys here: a, b, c
        <path>.<key>: missing required key

    ``path`` is the key path of ``d`` ("" at the top level).
    """
    valid = [str(v) for v in valid]
    for k in d:
        if str(k) not in valid:
            where = f"{path}.{k}" if path else str(k)
            raise ConfigError(f"{where}: unknown key{suggest(k, valid)}; valid keys here: {', '.join(valid)}")
    for k in required:
        if k not in d:
            where = f"{path}.{k}" if path else str(k)
            raise ConfigError(f"{where}: missing required key")
