"""``crossovers.csv``: one row per line intersection (docs/outputs.md)."""

from __future__ import annotations

import numpy as np

from .atomic import atomic_write_text
from .columns import CROSSOVER_COLUMNS, csv_text_field, format_float_column, metadata_lines


def write_crossovers_csv(path, crossovers, metadata: dict | None = None) -> None:
    """Write ``crossovers.csv``: header row, one row per crossover (columns as
    :data:`CROSSOVER_COLUMNS`, ``diff_mgal = value_a_mgal - value_b_mgal - continuation_mgal``).

    Parameters
    ----------
    crossovers : gravsurvey.crossovers.Crossovers
    """
    dec = {
        "easting_m": 3,
        "northing_m": 3,
        "time_a_s": 3,
        "time_b_s": 3,
        "height_a_m": 3,
        "height_b_m": 3,
        "value_a_mgal": 4,
        "value_b_mgal": 4,
        "continuation_mgal": 4,
        "diff_mgal": 4,
        "angle_deg": 2,
    }
    parts = []
    for c in CROSSOVER_COLUMNS:
        a = getattr(crossovers, c)
        if c in dec:
            parts.append(format_float_column(a, dec[c]))
        else:
            parts.append([csv_text_field(str(x)) for x in np.asarray(a).tolist()])
    rows = [f"# {m}" for m in metadata_lines(metadata)]
    rows += [",".join(CROSSOVER_COLUMNS)] + [",".join(r) for r in zip(*parts)]
    atomic_write_text(path, "\n".join(rows) + "\n")
