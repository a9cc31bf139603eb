"""docs/config.md's generated key reference (``python -m gravsurvey.settings --doc``)."""

from __future__ import annotations

import sys
from typing import Annotated, Any, Literal, get_args, get_origin

from pydantic import (
    BaseModel,
)

from ..io.csv import DEFAULT_COLUMNS
from ..io.mcap import DEFAULT_JSON_FIELDS

from .schema import (
    ChecksSection,
    CsvColumns,
    CsvInputs,
    CsvSection,
    DriftSection,
    FlightChecksSection,
    TimeOffsetsSection,
    FlightSection,
    GravimeterSection,
    GridSection,
    InitialSection,
    InputsSection,
    JsonFields,
    LevellingSection,
    LinesSection,
    McapSection,
    ModelSection,
    NavSection,
    OutputSection,
    PostprocessSection,
    ProcessingSection,
    SurveyFile,
    SurveySection,
    TieReadingSection,
    TieSection,
    TopicsSection,
    UnitsSection,
    WindowSection,
    three_numbers,
)


# ============================================================================ docs/config.md
def _role_section(model: Any, role: str) -> type:
    return next(a for a in get_args(model.model_fields[role].annotation) if a is not type(None))


#: sections of the generated reference: (heading, key prefix, model)
DOC_SECTIONS: list[tuple[str, str, Any]] = [
    ("Top level", "", SurveyFile),
    ("`survey`", "survey.", SurveySection),
    ("`processing`", "processing.", ProcessingSection),
    ("Flights (`flights[i]`)", "", FlightSection),
    ("`flights[i].inputs`", "inputs.", InputsSection),
    ("`flights[i].inputs.csv`", "inputs.csv.", CsvInputs),
    ("`flights[i].inputs.gravimeter`", "inputs.gravimeter.", GravimeterSection),
    ("`flights[i].inputs.gravimeter.nav`", "inputs.gravimeter.nav.", NavSection),
    ("`flights[i].topics`", "topics.", TopicsSection),
    ("`flights[i].mcap`", "mcap.", McapSection),
    ("`flights[i].csv`", "csv.", CsvSection),
    ("`flights[i].mcap.units`, `flights[i].csv.units`", "units.", UnitsSection),
    *[
        (f"`flights[i].mcap.json_fields.{role}`", f"mcap.json_fields.{role}.", _role_section(JsonFields, role))
        for role in DEFAULT_JSON_FIELDS
    ],
    *[
        (f"`flights[i].csv.columns.{role}`", f"csv.columns.{role}.", _role_section(CsvColumns, role))
        for role in DEFAULT_COLUMNS
    ],
    ("`flights[i].checks`", "checks.", FlightChecksSection),
    ("`flights[i].time_offsets_s`", "time_offsets_s.", TimeOffsetsSection),
    ("`flights[i].initial`", "initial.", InitialSection),
    ("`flights[i].lines`, `lines.windows[j]`", "", WindowSection),
    ("`flights[i].tie`", "tie.", TieSection),
    ("`flights[i].tie.before`, `flights[i].tie.after`", "", TieReadingSection),
    ("`model`: 3D-INM Kalman filter (docs/method.md)", "", ModelSection),
    ("`lines`: line segmentation (docs/outputs.md)", "", LinesSection),
    ("`postprocess`: per-line post-processor (docs/wavelet.md)", "", PostprocessSection),
    ("`drift`: gravimeter drift from the lines (docs/method.md)", "", DriftSection),
    ("`output`", "", OutputSection),
    ("`checks`: gaps, clocks, consistency, plausibility (docs/reliability.md)", "", ChecksSection),
    ("`levelling`: crossover levelling (gravsurvey/levelling.py)", "", LevellingSection),
    ("`grid`: gridding (gravsurvey/grid.py)", "", GridSection),
]
GENERATED_BEGIN = "<!-- BEGIN GENERATED REFERENCE: python -m gravsurvey.settings --doc; do not edit by hand -->"
GENERATED_END = "<!-- END GENERATED REFERENCE -->"


def _type_text(ann, field) -> str:
    """Markdown type of a field: choices, number/integer/bool/string/mapping/list, limits, null."""
    if isinstance(field.json_schema_extra, dict) and "type_text" in field.json_schema_extra:
        return str(field.json_schema_extra["type_text"])
    args = [a for a in get_args(ann) if a is not type(None)] if get_origin(ann) is not None else []
    nullable = type(None) in get_args(ann)
    base = args[0] if nullable and len(args) == 1 else ann
    if get_origin(base) is Literal:
        t = " \\| ".join(f"`{c}`" for c in get_args(base))
    elif base is bool:
        t = "bool"
    elif base is float:
        t = "number"
    elif base is int:
        t = "integer"
    elif base is str:
        t = "string"
    elif any(getattr(m, "func", None) is three_numbers for m in field.metadata) or (
        get_origin(base) is Annotated and any(getattr(m, "func", None) is three_numbers for m in get_args(base)[1:])
    ):
        t = "list of 3 numbers"
    elif get_origin(base) is list:
        t = "list"
    elif base is dict or (isinstance(base, type) and issubclass(base, BaseModel)):
        t = "mapping"
    else:
        t = "see meaning"
    limits = []
    for m in field.metadata:
        for attr, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            if getattr(m, attr, None) is not None:
                limits.append(f"{op} {getattr(m, attr):g}")
    if limits:
        t += " " + ", ".join(limits)
    return t + (" or null" if nullable else "")


def _default_text(field) -> str:
    if field.is_required():
        return "required"
    if field.default_factory is not None:
        v = field.default_factory()
        if isinstance(v, BaseModel):
            return "below"
    else:
        v = field.default
    if v is None:
        return "null"
    if isinstance(v, bool):
        return f"`{str(v).lower()}`"
    if isinstance(v, str):
        return f"`{v}`"
    if isinstance(v, float):
        return f"{v:g}"
    return f"`{v}`" if isinstance(v, list) and v else (f"{v}" if v != [] else "[]")


def reference_markdown() -> str:
    """The generated key reference of docs/config.md (between the GENERATED markers)."""
    out = [GENERATED_BEGIN, ""]
    for heading, prefix, model in DOC_SECTIONS:
        out += [
            f"### {heading}",
            "",
            (model.__doc__ or "").strip().split("\n")[0],
            "",
            "| key | type | default | meaning |",
            "|---|---|---|---|",
        ]
        for name, field in model.model_fields.items():
            key = f"{prefix}{field.alias or name}"
            desc = (field.description or "").replace("|", "\\|")
            out.append(f"| `{key}` | {_type_text(field.annotation, field)} | {_default_text(field)} | {desc} |")
        out.append("")
    out.append(GENERATED_END)
    return "\n".join(out)


def splice_reference(doc_text: str) -> str:
    """``doc_text`` with its generated section replaced by :func:`reference_markdown`."""
    a, b = doc_text.find(GENERATED_BEGIN), doc_text.find(GENERATED_END)
    if a < 0 or b < a:
        raise ValueError("docs/config.md has no generated reference markers")
    return doc_text[:a] + reference_markdown() + doc_text[b + len(GENERATED_END) :]


def main(argv=None) -> int:
    """``python -m gravsurvey.settings --doc [docs/config.md]``: rewrite the generated reference;
    ``--check``: exit 1 when the file's reference differs from the schema."""
    import argparse
    from pathlib import Path

    ap = argparse.ArgumentParser(prog="python -m gravsurvey.settings")
    ap.add_argument("--doc", action="store_true", help="rewrite the generated reference in the file")
    ap.add_argument("--check", action="store_true", help="exit 1 if the file's reference is out of date")
    ap.add_argument("path", nargs="?", default="docs/config.md")
    a = ap.parse_args(argv)
    p = Path(a.path)
    text = p.read_text(encoding="utf-8")
    new = splice_reference(text)
    if a.check:
        if new != text:
            print(
                f"{p}: generated reference differs from gravsurvey/settings; run python -m gravsurvey.settings --doc",
                file=sys.stderr,
            )
            return 1
        return 0
    if a.doc:
        p.write_text(new, encoding="utf-8")
        return 0
    print(reference_markdown())
    return 0
