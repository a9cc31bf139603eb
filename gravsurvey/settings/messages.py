"""Validation failures in gravsurvey's words: one :class:`~gravsurvey.errors.ConfigError` line
naming the full key path and what was expected."""

from __future__ import annotations

import re
from typing import Any, get_args, get_origin

from pydantic import (
    BaseModel,
    ValidationError,
)

from ..errors import ConfigError, suggest, unknown_key_text

from .schema import Section, SurveyFile


# ============================================================================ errors
def key_path_text(prefix: str, loc) -> str:
    out = prefix
    for part in loc:
        if isinstance(part, str) and part.startswith("<"):
            continue  # a union member's tag (schema.Tag("<...>")), not a key
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out = f"{out}.{part}" if out else str(part)
    return out


def value_text(v) -> str:
    return f"{v!r:.60}"


def _choices(expected: str) -> list[str]:
    return [c.strip().strip("'\"") for c in re.split(r",| or ", expected) if c.strip()]


def _limits_text(field, ctx: dict) -> str:
    """``" > 0"``, ``" in [1, 5]"``, ``" in (0, 45)"`` from a field's limits (or the error's), or ``""``."""
    lim = {
        a: getattr(m, a)
        for m in (field.metadata if field is not None else ())
        for a in ("gt", "ge", "lt", "le")
        if getattr(m, a, None) is not None
    } or {a: x for a, x in ctx.items() if a in ("gt", "ge", "lt", "le")}
    lo = [(a, x) for a, x in lim.items() if a in ("gt", "ge")]
    hi = [(a, x) for a, x in lim.items() if a in ("lt", "le")]
    if lo and hi:
        (la, lx), (ha, hx) = lo[0], hi[0]
        return f" in {'(' if la == 'gt' else '['}{lx:g}, {hx:g}{')' if ha == 'lt' else ']'}"
    if lim:
        a, x = next(iter(lim.items()))
        return f" {dict(gt='>', ge='>=', lt='<', le='<=')[a]} {x:g}"
    return ""


def _message(err: Any, field=None) -> tuple[tuple, str]:
    """(extra key path, text) of one pydantic error in gravsurvey's words (``field``: the
    schema field at the error's location, for its limits and description)."""
    t, ctx, v = err["type"], err.get("ctx") or {}, err.get("input")
    if t == "gravsurvey":
        return tuple(ctx.get("key", ())), ctx["message"]
    if t == "unknown_key":
        valid = ctx["valid"]
        return (ctx["key"],), unknown_key_text(ctx["key"], valid)
    if t in ("mapping", "model_type", "dict_type"):
        return (), f"expected a mapping, got {type(v).__name__} {value_text(v)}"
    if t == "missing":
        hint = f" ({field.description})" if field is not None and field.description else ""
        return (), f"missing required key{hint}"
    if t == "literal_error":
        ch = _choices(ctx.get("expected", ""))
        return (), f"expected one of {', '.join(ch)}, got {value_text(v)}{suggest(v, ch)}"
    if t in ("float_type", "float_parsing"):
        return (), f"expected a number{_limits_text(field, ctx)}, got {value_text(v)}"
    if t == "finite_number":
        return (), f"expected a finite number{_limits_text(field, ctx)}, got {value_text(v)}"
    if t in ("int_type", "int_parsing", "int_from_float"):
        return (), f"expected an integer{_limits_text(field, ctx)}, got {value_text(v)}"
    if t == "bool_type":
        return (), f"expected true or false, got {value_text(v)}"
    if t == "string_type":
        return (), f"expected a string, got {value_text(v)}"
    if t == "string_too_short":
        return (), f"expected a non-empty string, got {value_text(v)}"
    if t == "list_type":
        return (), f"expected a list, got {value_text(v)}"
    if t in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        if t == "too_short" and lo == 1:
            return (), f"expected a non-empty list, got {value_text(v)}"
        want = f"at least {lo}" if t == "too_short" else f"at most {hi}"
        return (), f"expected {want} item(s), got {ctx.get('actual_length')}: {value_text(v)}"
    if t in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        ann = field.annotation if field is not None else type(v)
        kind = "an integer" if ann is int or int in get_args(ann) else "a number"
        return (), f"expected {kind}{_limits_text(field, ctx)}, got {value_text(v)}"
    return (), f"{err['msg']}, got {value_text(v)}"


def _field_at(model: type, loc) -> Any:
    """The schema field at ``loc`` below ``model`` (None when the path leaves the schema)."""
    field: Any = None
    cur: Any = model
    for part in loc:
        if isinstance(part, int):
            args = [a for a in get_args(cur) if a is not type(None)] if cur is not None else []
            cur = args[0] if args else None
            continue
        while cur is not None and not (isinstance(cur, type) and issubclass(cur, BaseModel)):
            args = [a for a in get_args(cur) if a is not type(None)]
            cur = (
                args[0]
                if len(args) == 1 and get_origin(cur) is not list
                else (args[0] if get_origin(cur) is list else None)
            )
            if get_origin(cur) is list:
                break
        if not (isinstance(cur, type) and issubclass(cur, BaseModel)) or part not in cur.model_fields:
            return None
        field = cur.model_fields[part]
        cur = field.annotation
    return field


def config_error(exc: ValidationError, key_path: str = "", model: type | None = None) -> ConfigError:
    """The first problem of ``exc`` as a one-line :class:`ConfigError` naming the full key path.

    ``<key path>: <what was expected>, got <value>``; an unknown key gets the nearest valid name
    (:func:`gravsurvey.errors.suggest`) and the valid keys of its mapping.
    """
    err = exc.errors(include_url=False)[0]
    field = _field_at(model, err["loc"]) if model is not None else None
    extra, text = _message(err, field)
    return ConfigError(f"{key_path_text(key_path, tuple(err['loc']) + extra) or key_path or 'config'}: {text}")


def validate_section(model: type[Section], data: Any, key_path: str = "") -> Any:
    """``model`` validated from ``data`` (None: the defaults); :class:`ConfigError` otherwise."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise config_error(exc, key_path, model) from None


def parse_survey(raw: dict) -> SurveyFile:
    """The whole loaded YAML mapping validated against :class:`SurveyFile`."""
    return validate_section(SurveyFile, raw, "")
