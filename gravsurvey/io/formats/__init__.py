"""Readers for real gravimeter, marine-gravity and navigation files (see docs/input-formats.md).

Each ``read_<format>(path, ...)`` returns a :class:`~gravsurvey.io.formats.common.FormatTable`:
int64 Unix-ns UTC stamps and plain numpy columns, SI inside, with skipped lines counted and
reported.
"""

from .common import FormatTable
from .mgd77t import read_mgd77t, read_mgd77t_header

__all__ = ["FormatTable", "read_mgd77t", "read_mgd77t_header"]
from .nmea import read_nmea  # noqa: E402

__all__ += ["read_nmea"]
from .dgs import read_at1a, read_dgs_laptop, read_dgs_raw  # noqa: E402

__all__ += ["read_at1a", "read_dgs_laptop", "read_dgs_raw"]
from .bgm import read_bgm_rgs, read_bgm_serial  # noqa: E402
from .zls import read_zls  # noqa: E402

__all__ += ["read_bgm_rgs", "read_bgm_serial", "read_zls"]
from .trajectory import read_trajectory  # noqa: E402

__all__ += ["read_trajectory"]
from .rtklib import read_rtklib_pos  # noqa: E402

__all__ += ["read_rtklib_pos"]
