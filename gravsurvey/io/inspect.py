"""``gravsurvey inspect FILE...``: what is in a log file, per channel, and does it look sane.

MCAP and channel CSV files are described channel by channel; any other file is tried with the
real gravimeter and navigation readers
(:func:`gravsurvey.io.formats.flight.detect_format`) and described as one channel.

:func:`inspect_files` returns JSON-serialisable dicts (``--json``); :func:`format_inspect`
renders them as text.  A file that cannot be read gives a report with an ``error`` entry
instead of an exception, so one bad file does not hide the others.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gravsurvey.errors import GravsurveyError
from gravsurvey.io import checks as ck
from gravsurvey.io.csv import read_csv_channel, sniff_csv_role
from gravsurvey.io.ingest import IngestOptions, apply_units
from gravsurvey.io.mcap import read_mcap
from gravsurvey.utc import utc_iso


def _span(t):
    if len(t) == 0:
        return {"start_utc": None, "end_utc": None, "duration_s": 0.0}
    return {
        "start_utc": utc_iso(t.min(), digits=9),
        "end_utc": utc_iso(t.max(), digits=9),
        "duration_s": float((int(t.max()) - int(t.min())) * 1e-9),
    }


def _channel_report(role, time_ns, values, units):
    """Time-base and plausibility report of one decoded channel (values in SI)."""
    keys = list(values)
    t, vals, rep = ck.repair_time(time_ns, [values[k] for k in keys])
    values = dict(zip(keys, vals))
    f = ck.time_findings(role, rep, int(t[0]) if len(t) else 0) + ck.check_epoch(role, t)
    if role == "imu":
        f += ck.check_imu(
            t, values["specific_force"], values["angular_rate"], rep.nominal_step_ns, units["accel"], units["gyro"]
        )
        t_s = (t - t[0]) * 1e-9 if len(t) else None
        f += ck.saturated_imu(values["specific_force"], values["angular_rate"], t_s, units["accel"], units["gyro"])[1]
    elif role == "gnss":
        f += ck.check_gnss(values["lat_deg"], values["lon_deg"])
        f += ck.check_height(role, values["height"], units["height"])
    elif role != "gradient":  # the gradient's unit/symmetry checks run at ingestion
        f += ck.check_height(role, values["height"], units["height"])
    return {
        "role": role,
        **_time_base(t, rep),
        "checks": [{"check": x.check, "level": x.level, "message": x.message} for x in f],
    }


def _time_base(t, rep):
    """The report entries of a repaired time base (``t`` and ``rep`` of :func:`checks.repair_time`)."""
    rate = 1e9 / rep.nominal_step_ns if np.isfinite(rep.nominal_step_ns) else None
    t0 = int(t[0]) if len(t) else 0
    return {
        "samples": rep.n_out,
        "measurement_time": _span(t),
        "nominal_rate_hz": rate,
        "duplicates_dropped": rep.duplicates + rep.conflicting_duplicates,
        # "coarse" or "jitter": the logger's stamps rebuilt from the sample count (checks.rebuild_time_base)
        "stamps_rebuilt": rep.rebuilt or None,
        "backward_steps": rep.n_backward,
        "gaps": rep.n_gaps,
        "gap_list_s": [[(a - t0) * 1e-9, (b - t0) * 1e-9] for a, b in rep.gaps],
        "irregular_step_fraction": rep.irregular_fraction,
    }


def options_for(path, config):
    """The ingestion settings a survey config gives a file: those of the flight that names
    it (same resolved path, else same file name), else the first flight's.

    Parameters
    ----------
    path : path
    config : gravsurvey.config.SurveyConfig

    Returns
    -------
    options : IngestOptions
    note : str or None
        Which flight's settings were used, or why none matched.
    """
    p = Path(path).resolve()
    flights = list(config.flights)
    if not flights:
        return IngestOptions(), f"{config.path}: no flights; default settings used"
    for fl in flights:
        if any(Path(q).resolve() == p for q in fl.ingest.input_paths(config.base_dir)):
            return fl.ingest, f"settings of flights[{fl.index}] ({fl.name}) in {config.path}"
    for fl in flights:
        if any(Path(q).name == p.name for q in fl.ingest.input_paths(config.base_dir)):
            return fl.ingest, (f"settings of flights[{fl.index}] ({fl.name}) in {config.path} (matched by file name)")
    fl = flights[0]
    return fl.ingest, (f"not an input of {config.path}; settings of flights[{fl.index}] ({fl.name}) used")


def damage_lines(rep) -> list[str]:
    """What was damaged in one file's report (empty: nothing); ``inspect`` exits 1 if any."""
    out = []
    if rep.get("error"):
        out.append(rep["error"])
    if rep.get("salvage"):
        out.append(rep["salvage"]["summary"])
    out += [n for n in rep.get("notes", []) if "damaged" in n]
    out += rep.get("csv_damage", [])  # a CSV's last line cut short
    for ch in rep.get("channels", []):
        if ch.get("value_check_dropped"):
            out.append(
                f"{ch['topic']}: {ch['value_check_dropped']} samples without a chunk CRC "
                "failed the damage checks (corrupted values or time stamps)"
            )
    return out


def inspect_files(paths, options: IngestOptions | None = None, config=None) -> list[dict]:
    """Inspect MCAP and CSV log files.

    Parameters
    ----------
    paths : iterable of path
        ``*.mcap`` files (any topics), or channel CSV files (channel guessed from the header
        columns, or from ``options.csv_paths`` when the file is named there).
    options : IngestOptions, optional
        Topics, JSON fields, CSV columns/time format/units; defaults when None.
    config : gravsurvey.config.SurveyConfig, optional
        A survey config: each file is inspected with the settings of the flight that names it
        (:func:`options_for`); overrides ``options``.

    Returns
    -------
    list of dict
        One JSON-serialisable report per file: ``file``, ``format``, ``size_bytes``, and for
        MCAP ``profile``, ``library``, ``chunks``, ``compression``, ``salvage``, ``notes``,
        ``channels`` (per channel: ``topic``, ``schema``, ``encoding``, ``messages``,
        ``log_time`` span, and for sensor channels the :func:`_channel_report` entries);
        for CSV ``csv_damage`` (a last line cut short), ``notes``;
        ``error`` instead when the file could not be read; ``damage``: the lines of
        :func:`damage_lines` (empty when the file is sound); ``settings`` with ``config``.
    """
    out = []
    for p in paths:
        p = os.fspath(p)
        rep = {"file": p}
        o = options or IngestOptions()
        if config is not None:
            o, rep["settings"] = options_for(p, config)
        try:
            rep["size_bytes"] = os.path.getsize(p)
            if p.lower().endswith(".mcap"):
                rep.update(_inspect_mcap(p, o))
            else:
                rep.update(_inspect_csv(p, o))
        except GravsurveyError as exc:
            rep["error"] = str(exc)
        except OSError as exc:
            rep["error"] = f"{p}: cannot read ({exc.strerror})"
        rep["damage"] = damage_lines(rep)
        out.append(rep)
    return out


def _inspect_mcap(path, o):
    c = read_mcap(
        path, topics=o.topics, json_fields=o.json_fields, check_crc=o.check_crc, max_record_bytes=o.max_record_bytes
    )
    rep = {
        "format": "mcap",
        "profile": c.profile,
        "library": c.library,
        "chunks": c.chunks,
        "compression": sorted(c.compressions),
        "notes": list(c.notes),
        "salvage": None,
        "channels": [],
    }
    if c.salvage:
        s = c.salvage
        rep["salvage"] = {
            "damaged_at_byte": s.offset,
            "reason": s.reason,
            "recovered_messages": s.recovered,
            "lost_messages": s.lost_messages,
            "summary": s.describe(path),
            "regions": [r.as_dict() for r in s.regions],
        }
    if c.orphan_messages:
        rep["notes"].append(f"{c.orphan_messages} messages on undefined channels")
    for cid in sorted(c.channels):
        ch = c.channels[cid]
        lt = c.log_times.get(cid, np.zeros(0, np.int64))
        entry = {
            "topic": ch.topic,
            "channel_id": cid,
            "schema": c.schema_name(cid),
            "encoding": ch.message_encoding,
            "messages": c.counts.get(cid, 0),
            "log_time": _span(lt),
            "role": None,
        }
        blk = c.decoded.get(cid)
        if blk is not None and len(blk.time_ns):
            role = next((r for r, t in o.topics.items() if t == ch.topic), None) or c.role_of_schema(cid)
            vals = dict(blk.values)
            if role == "altimeter":
                vals = {"height": vals["height"]}
            vals = apply_units(role, vals, o.mcap_units)
            entry.update(_channel_report(role, blk.time_ns, vals, o.mcap_units))
            entry["time_source"] = "header.stamp" if ch.message_encoding == "cdr" else "JSON field"
            if blk.log_time_used:
                entry["time_source"] += f" ({blk.log_time_used} fell back to log_time)"
            entry["undecodable"] = blk.undecodable
            entry["value_check_dropped"] = blk.value_check_dropped
        rep["channels"].append(entry)
    return rep


def _suggest_from_header(path, delimiter=","):
    """:func:`gravsurvey.io.columns.suggest_csv_settings` for the first non-comment line of a CSV
    (empty when it cannot be read)."""
    import csv as _csv

    from gravsurvey.io.columns import suggest_csv_settings

    try:
        with open(path, newline="", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.strip() and not line.startswith("#"):
                    return suggest_csv_settings(next(_csv.reader([line], delimiter=delimiter)))
    except OSError:
        pass
    return {}


def _inspect_csv(path, o):
    role = None
    for r, q in o.csv_paths.items():
        if Path(q).name == Path(path).name:
            role = r
    role = role or sniff_csv_role(path)
    if role == "truth":
        return {
            "format": "csv",
            "channels": [],
            "notes": ["simulator truth file (docs/formats.md, truth.csv), not a sensor log"],
        }
    if role is None:
        vendor = _inspect_vendor(path)
        if vendor is not None:
            return vendor
        # the formats _inspect_vendor has just tried, in its order
        from gravsurvey.io.formats.flight import DETECT_ORDER

        tried = ", ".join(name for name, _, _ in DETECT_ORDER)
        suggestion = _suggest_from_header(path, o.csv_delimiter)
        rep = {
            "format": "csv",
            "error": (
                f"{path}: header matches no channel (imu, altimeter, gnss columns of docs/input-formats.md) "
                f"and the file is none of the gravimeter or navigation formats ({tried}); a channel "
                "CSV with other column names needs them: --config survey.yaml"
                + ("; suggested from its header (check before use):" if suggestion.get("columns") else "")
            ),
        }
        if suggestion.get("columns"):
            rep["suggested_csv"] = suggestion
        return rep
    notes, damage = [], []
    t, vals = read_csv_channel(
        path,
        role,
        o.csv_columns.get(role),
        o.csv_time_format,
        o.csv_units,
        o.csv_delimiter,
        o.gps_leap_seconds,
        notes=notes,
        data_loss=damage,
    )
    entry = {
        "topic": None,
        "schema": "csv",
        "encoding": "csv",
        "messages": len(t),
        "time_source": f"column ({o.csv_time_format})",
    }
    entry.update(_channel_report(role, t, vals, o.csv_units))
    return {"format": "csv", "channels": [entry], "csv_damage": damage, "notes": [n for n in notes if n not in damage]}


def _inspect_vendor(path):
    """Report of a real gravimeter or navigation file, or None when no reader takes it
    (:func:`gravsurvey.io.formats.flight.detect_format`)."""
    from gravsurvey.io.formats.flight import detect_format

    found = detect_format(path)
    if found is None:
        return None
    fmt, kind, table, caught = found
    t, _, rep = ck.repair_time(table.time_ns, [])
    if kind == "navigation":
        use = "the navigation of inputs.gravimeter.nav or inputs.nav"
    elif fmt == "dgs_raw":
        use = "raw counts, not processed (they need the meter's calibration)"
    else:
        use = f"process it with inputs.gravimeter: {{format: {fmt}, file: ...}}"
    channel = {
        "topic": None,
        "schema": fmt,
        "encoding": "text",
        "messages": len(table),
        "role": kind,
        "time_source": str(table.meta.get("time_source", "file")),
        **_time_base(t, rep),
        "columns": {k: table.units.get(k, "") for k in table.columns},
        "checks": [],
    }
    notes = [f"{kind} file, format {fmt} (docs/input-formats.md): {use}"]
    notes += [f"{table.n_skipped} of {table.n_lines} content lines skipped"] if table.n_skipped else []
    notes += list(table.notes) + list(caught)
    return {"format": fmt, "channels": [channel], "notes": notes}


def format_inspect(reports) -> str:
    """Human-readable text of :func:`inspect_files` reports."""
    lines = []
    for rep in reports:
        head = f"{rep['file']}"
        if "format" in rep:
            head += f"  [{rep['format']}"
            if rep.get("profile") is not None and rep["format"] == "mcap":
                head += (
                    f", profile {rep['profile'] or '-'}, {rep.get('chunks', 0)} chunks "
                    f"({', '.join(rep.get('compression', [])) or 'unchunked'})"
                )
            head += f", {rep.get('size_bytes', 0)} bytes]"
        lines.append(head)
        if rep.get("settings"):
            lines.append(f"  using {rep['settings']}")
        if "error" in rep:
            lines.append(f"  ERROR: {rep['error']}")
            if rep.get("suggested_csv"):
                from gravsurvey.io.columns import suggestion_yaml

                lines += ["    " + x for x in suggestion_yaml(rep["suggested_csv"])]
                lines += [f"    # {n}" for n in rep["suggested_csv"].get("notes", [])]
            continue
        for d in rep.get("damage", []):
            lines.append(f"  DAMAGED: {d}")
        for n in rep.get("notes", []):
            lines.append(f"  note: {n}")
        if not rep.get("channels"):
            lines.append("  (no channels)")
            continue
        lines.append(
            f"  {'topic':<34} {'schema':<30} {'enc':<5} {'msgs':>8} {'span_s':>10} "
            f"{'rate_hz':>9} {'gaps':>5}  start (UTC)"
        )
        for ch in rep.get("channels", []):
            span = ch.get("measurement_time") or ch.get("log_time") or {}
            rate = ch.get("nominal_rate_hz")
            lines.append(
                f"  {str(ch.get('topic') or '-'):<34} {str(ch.get('schema') or '-'):<30} "
                f"{str(ch.get('encoding')):<5} {ch.get('messages', 0):>8} "
                f"{span.get('duration_s', 0.0):>10.3f} "
                f"{(f'{rate:.4g}' if rate else '-'):>9} {str(ch.get('gaps', '-')):>5}  "
                f"{span.get('start_utc') or '-'}"
            )
        for ch in rep.get("channels", []):
            if ch.get("role"):
                lines.append(f"  {ch['role']} ({ch.get('topic') or 'csv'}, time from {ch.get('time_source')}):")
                for x in ch.get("checks", []):
                    lines.append(f"    [{x['level']}] {x['message']}")
    return "\n".join(lines)
