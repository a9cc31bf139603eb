"""Sensor-log writers of the simulator: MCAP (JSON and ROS 2 CDR) and CSV, per docs/formats.md.

The writers share no code with the readers (``gravsurvey.io``); both sides are written from
docs/formats.md.  Everything here is deterministic: the same inputs give byte-identical files
(no wall clock, no random names inside the files).  Every file is written to a temporary file
in the destination directory and moved into place with ``os.replace`` only after all requested
files of the call were written completely, so an error never leaves a partial file behind and
never clobbers an older complete file.

Speed and memory: payloads are built in bulk, block by block (``_BLOCK`` samples: one numpy
structured-array pass per block of CDR messages; column-wise ``repr`` for JSON and CSV) and
streamed to the file, so memory does not grow with the flight length beyond the input arrays and
a few int64 index arrays; the per-message cost is the ``mcap`` Writer's.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
from mcap import __version__ as _MCAP_VERSION
from mcap.writer import CompressionType, IndexType, Writer

from gravsurvey import __version__ as _GRAVSURVEY_VERSION
from gravsurvey.errors import ConfigError, DataError

__all__ = [
    "FORMATS",
    "SensorLogs",
    "TRUTH_COLUMNS",
    "ros2_time",
    "utc_iso",
    "write_flight_logs",
    "write_truth_csv",
]

#: Log formats understood by :func:`write_flight_logs`.
FORMATS = ("mcap_json", "mcap_ros2", "csv")

#: Columns every truth.csv carries, in this order (docs/formats.md); extra columns follow.
TRUTH_COLUMNS = (
    "time_ns",
    "line",
    "lat_deg",
    "lon_deg",
    "height_m",
    "ve_mps",
    "vn_mps",
    "vu_mps",
    "roll_deg",
    "pitch_deg",
    "heading_deg",
    "disturbance_mgal",
    "anomaly_e_mgal",
    "anomaly_n_mgal",
    "anomaly_u_mgal",
    "dg_north_mgal",
    "dg_east_mgal",
)

_LIBRARY = f"gravsurvey/{_GRAVSURVEY_VERSION} mcap-python/{_MCAP_VERSION}"
_BLOCK = 16384  # samples encoded per bulk pass
_CHUNK_SIZE = 1024 * 1024  # bytes of uncompressed records per chunk (mcap default)
_NS = 1_000_000_000
_INT32_MAX = 2**31 - 1

# Fixed ROS frame ids (docs/formats.md).
FRAME_IMU = "imu"
FRAME_ALTIMETER = "altimeter"
FRAME_GNSS = "gnss"


@dataclass
class SensorLogs:
    """One flight's simulated sensor samples, ready to be written.

    Attributes
    ----------
    start_unix_ns : int
        Flight start (sample 0 of every channel), ns since the Unix epoch, UTC.  Named in the
        files' comments/metadata; every sample time must be >= it.
    imu_time_ns : ndarray of int64, shape (n,)
        IMU measurement times, ns since the Unix epoch, strictly increasing.
    specific_force_t : ndarray, shape (n, 3)
        Specific force ``F = a_inertial - G`` on the instrument triad, m/s^2.
    angular_rate_t : ndarray, shape (n, 3)
        Absolute angular rate of the triad resolved on the triad, rad/s.
    alt_time_ns : ndarray of int64, shape (m,)
        Altimeter measurement times, ns, strictly increasing.
    height_m : ndarray, shape (m,)
        Altimeter ellipsoidal height, m.
    gnss_time_ns : ndarray of int64, shape (k,), or None
        GNSS measurement times, ns, strictly increasing; None: no GNSS channel.
    lat_deg, lon_deg : ndarray, shape (k,), or None
        GNSS geodetic latitude and longitude, degrees (WGS84).
    gnss_height_m : ndarray, shape (k,), or None
        GNSS ellipsoidal height, m.
    accel_sigma_mps2 : float or array_like, shape (3,)
        Accelerometer white-noise standard deviation per sample, m/s^2 (ROS covariance
        ``diag(sigma^2)``; 0 allowed).
    gyro_sigma_radps : float or array_like, shape (3,)
        Gyro white-noise standard deviation per sample, rad/s.
    gnss_sigma_m : float or array_like, shape (3,)
        GNSS position standard deviation (East, North, Up), m.
    gradient_time_ns : ndarray of int64, shape (j,), or None
        Gravity-gradiometer measurement times, ns; None: no gradient channel.
    gradient_t_eotvos : ndarray, shape (j, 6), or None
        Gravitation gradient tensor on the triad, the 6 independent components
        ``xx, xy, xz, yy, yz, zz``, Eotvos (1 E = 1e-9 1/s^2).
    """

    start_unix_ns: int
    imu_time_ns: np.ndarray
    specific_force_t: np.ndarray
    angular_rate_t: np.ndarray
    alt_time_ns: np.ndarray
    height_m: np.ndarray
    gnss_time_ns: np.ndarray | None = None
    lat_deg: np.ndarray | None = None
    lon_deg: np.ndarray | None = None
    gnss_height_m: np.ndarray | None = None
    accel_sigma_mps2: float | Sequence[float] = 0.0
    gyro_sigma_radps: float | Sequence[float] = 0.0
    gnss_sigma_m: float | Sequence[float] = 0.0
    gradient_time_ns: np.ndarray | None = None
    gradient_t_eotvos: np.ndarray | None = None


# --------------------------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------------------------


def _times(value, what: str) -> np.ndarray:
    """Integer ns stamps, shape (n,), n >= 1, non-negative and strictly increasing -> int64."""
    a = np.asarray(value)
    if a.ndim != 1 or a.size == 0:
        raise DataError(f"{what}: expected a non-empty 1-D array of int ns, got shape {a.shape}")
    if a.dtype.kind not in "iu":
        raise DataError(f"{what}: expected integer Unix ns (int64), got dtype {a.dtype}")
    if a.dtype.kind == "u" and a.max() > np.iinfo(np.int64).max:
        raise DataError(f"{what}: time stamp beyond int64 ns")
    a = a.astype(np.int64, copy=False)
    if a[0] < 0:
        raise DataError(f"{what}: negative Unix ns {int(a[0])} (expected >= 0)")
    if a.size > 1 and not np.all(np.diff(a) > 0):
        k = int(np.flatnonzero(np.diff(a) <= 0)[0])
        raise DataError(
            f"{what}: times must strictly increase; sample {k + 1} ({int(a[k + 1])}) <= sample {k} ({int(a[k])})"
        )
    return a


def _floats(value, what: str, shape: tuple) -> np.ndarray:
    """Finite float64 array of the given shape (copy-free when already float64)."""
    a = np.asarray(value)
    if a.dtype.kind not in "fiu":
        raise DataError(f"{what}: expected real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64, copy=False)
    if a.shape != shape:
        raise DataError(f"{what}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        k = int(np.flatnonzero(~np.isfinite(a.reshape(a.shape[0], -1)).any(axis=1))[0])
        raise DataError(f"{what}: non-finite value at sample {k} (expected finite floats)")
    return a


def _sigma3(value, what: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(3, float(a))
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise DataError(f"{what}: expected a finite sigma >= 0 (scalar or 3 values), got {value!r}")
    return a


@dataclass
class _Checked:
    start_unix_ns: int
    imu_t: np.ndarray
    f_t: np.ndarray
    w_t: np.ndarray
    alt_t: np.ndarray
    alt_h: np.ndarray
    gnss_t: np.ndarray | None
    lat: np.ndarray | None
    lon: np.ndarray | None
    gnss_h: np.ndarray | None
    accel_sigma: np.ndarray
    gyro_sigma: np.ndarray
    gnss_sigma: np.ndarray
    grad_t: np.ndarray | None = None
    grad: np.ndarray | None = None


def _check_logs(logs: SensorLogs, need_int32_seconds: bool) -> _Checked:
    if not isinstance(logs, SensorLogs):
        raise DataError(f"sensor logs: expected a SensorLogs, got {type(logs).__name__}")
    if not isinstance(logs.start_unix_ns, (int, np.integer)) or isinstance(logs.start_unix_ns, bool):
        raise DataError(f"start_unix_ns: expected an integer ns, got {logs.start_unix_ns!r}")
    start = int(logs.start_unix_ns)
    if start < 0:
        raise DataError(f"start_unix_ns: expected an integer ns >= 0, got {logs.start_unix_ns!r}")

    imu_t = _times(logs.imu_time_ns, "imu time_ns")
    n = imu_t.size
    f_t = _floats(logs.specific_force_t, "imu specific_force_t", (n, 3))
    w_t = _floats(logs.angular_rate_t, "imu angular_rate_t", (n, 3))
    alt_t = _times(logs.alt_time_ns, "altimeter time_ns")
    alt_h = _floats(logs.height_m, "altimeter height_m", (alt_t.size,))

    gnss_fields = (logs.gnss_time_ns, logs.lat_deg, logs.lon_deg, logs.gnss_height_m)
    if all(v is None for v in gnss_fields):
        gnss_t = lat = lon = gnss_h = None
    elif any(v is None for v in gnss_fields):
        raise DataError("gnss: gnss_time_ns, lat_deg, lon_deg, gnss_height_m must be all given or all None")
    else:
        gnss_t = _times(logs.gnss_time_ns, "gnss time_ns")
        k = gnss_t.size
        lat = _floats(logs.lat_deg, "gnss lat_deg", (k,))
        lon = _floats(logs.lon_deg, "gnss lon_deg", (k,))
        gnss_h = _floats(logs.gnss_height_m, "gnss height_m", (k,))
        if np.any(np.abs(lat) > 90.0):
            raise DataError("gnss lat_deg: latitude outside [-90, 90] degrees")

    for name, t in (("imu", imu_t), ("altimeter", alt_t), ("gnss", gnss_t)):
        if t is None:
            continue
        if t[0] < start:
            raise DataError(f"{name} time_ns: first sample {int(t[0])} before start_unix_ns {start}")
        if need_int32_seconds and t[-1] // _NS > _INT32_MAX:
            raise DataError(f"{name} time_ns: {int(t[-1])} beyond the ROS 2 int32 seconds stamp (year 2038)")

    if (logs.gradient_time_ns is None) != (logs.gradient_t_eotvos is None):
        raise DataError("gradient: gradient_time_ns and gradient_t_eotvos must be both given or both None")
    grad_t = grad = None
    if logs.gradient_time_ns is not None:
        grad_t = _times(logs.gradient_time_ns, "gradient time_ns")
        grad = _floats(logs.gradient_t_eotvos, "gradient gradient_t_eotvos", (grad_t.size, 6))
        if grad_t[0] < start:
            raise DataError(f"gradient time_ns: first sample {int(grad_t[0])} before start_unix_ns {start}")

    checked = _Checked(
        start,
        imu_t,
        f_t,
        w_t,
        alt_t,
        alt_h,
        gnss_t,
        lat,
        lon,
        gnss_h,
        _sigma3(logs.accel_sigma_mps2, "accel_sigma_mps2"),
        _sigma3(logs.gyro_sigma_radps, "gyro_sigma_radps"),
        _sigma3(logs.gnss_sigma_m, "gnss_sigma_m"),
    )
    checked.grad_t, checked.grad = grad_t, grad
    return checked


def _check_formats(formats: Iterable[str]) -> list[str]:
    if isinstance(formats, str):
        formats = [formats]
    wanted = []
    for f in formats:
        if f not in FORMATS:
            raise ConfigError(f"log format {f!r} unknown (expected some of {', '.join(FORMATS)})")
        if f not in wanted:
            wanted.append(f)
    return [f for f in FORMATS if f in wanted]  # fixed order: deterministic file list


def _check_flight_name(name: str) -> str:
    if not isinstance(name, str) or not name or name in (".", "..") or any(c in name for c in "/\\\0\n\r"):
        raise ConfigError(f"flight name {name!r}: expected a plain file-name stem (no / \\ NUL)")
    return name


# --------------------------------------------------------------------------------------------
# text helpers
# --------------------------------------------------------------------------------------------


def _reprs(a: np.ndarray) -> list[str]:
    """Shortest round-trip decimal strings of float64 values (Python ``repr``)."""
    return list(map(float.__repr__, a.tolist()))


def _ints(a: np.ndarray) -> list[str]:
    return list(map(int.__repr__, a.tolist()))


def utc_iso(unix_ns: int) -> str:
    """ISO 8601 UTC string with nanoseconds for integer Unix ns, e.g. ``2026-05-01T06:00:00.000000000Z``."""
    s, ns = divmod(int(unix_ns), _NS)
    d = _dt.datetime.fromtimestamp(s, tz=_dt.timezone.utc)
    return d.strftime("%Y-%m-%dT%H:%M:%S") + f".{ns:09d}Z"


def _comment_lines(comments: Iterable[str]) -> list[str]:
    """User comments as ``# ...`` lines (a comment with newlines gives several lines)."""
    if isinstance(comments, str):
        comments = [comments]
    out = []
    for c in comments:
        for line in str(c).splitlines() or [""]:
            out.append(("# " + line).rstrip())
    return out


# --------------------------------------------------------------------------------------------
# atomic multi-file write
# --------------------------------------------------------------------------------------------


class _AtomicFiles:
    """Open temporary files next to their targets; move them all into place on success.

    On any exception inside the ``with`` block every temporary file is removed and no target is
    touched.  Temporary files are created with mode 0o666 & ~umask, like an ordinary ``open``.
    """

    def __init__(self):
        self._pending: list[tuple[Path, Path]] = []

    def __enter__(self):
        return self

    def open(self, target: Path):
        target = Path(target)
        for k in range(1000):
            tmp = target.with_name(f".{target.name}.{os.getpid()}.{k}.tmp")
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            except FileExistsError:
                continue
            break
        else:  # pragma: no cover - 1000 stale temp files of this very pid
            raise DataError(f"{target}: cannot create a temporary file next to it")
        self._pending.append((tmp, target))
        return os.fdopen(fd, "wb")

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            for tmp, target in self._pending:
                os.replace(tmp, target)
        else:
            for tmp, _ in self._pending:
                try:
                    os.unlink(tmp)
                except FileNotFoundError:
                    pass
        return False


def _write_bytes_atomic(files: _AtomicFiles, target: Path, chunks: Iterable[bytes]) -> None:
    with files.open(target) as fh:
        for c in chunks:
            fh.write(c)
        fh.flush()
        os.fsync(fh.fileno())


# --------------------------------------------------------------------------------------------
# JSON payloads
# --------------------------------------------------------------------------------------------


def _json_schema(title: str, description: str, props: Mapping[str, tuple]) -> bytes:
    """A JSON Schema (2020-12) document for one flat message type."""
    properties = {}
    for key, (kind, desc) in props.items():
        if kind in ("vec3", "vec6"):
            size = 3 if kind == "vec3" else 6
            properties[key] = {
                "type": "array",
                "items": {"type": "number"},
                "minItems": size,
                "maxItems": size,
                "description": desc,
            }
        else:
            properties[key] = {"type": kind, "description": desc}
    doc = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": list(props),
    }
    return json.dumps(doc, indent=2).encode("utf-8")


_T_DESC = "measurement time, integer ns since the Unix epoch (UTC)"
JSON_SCHEMAS = {
    "/imu": (
        "gravsurvey.Imu",
        _json_schema(
            "gravsurvey.Imu",
            "IMU sample on the instrument triad",
            {
                "time_ns": ("integer", _T_DESC),
                "specific_force_t": ("vec3", "specific force F = a_inertial - G, m/s^2, triad"),
                "angular_rate_t": ("vec3", "absolute angular rate of the triad, rad/s, triad"),
            },
        ),
    ),
    "/altimeter": (
        "gravsurvey.Altimeter",
        _json_schema(
            "gravsurvey.Altimeter",
            "altimeter sample",
            {"time_ns": ("integer", _T_DESC), "height_m": ("number", "ellipsoidal height, m")},
        ),
    ),
    "/gnss": (
        "gravsurvey.Gnss",
        _json_schema(
            "gravsurvey.Gnss",
            "GNSS position (WGS84)",
            {
                "time_ns": ("integer", _T_DESC),
                "lat_deg": ("number", "geodetic latitude, degrees"),
                "lon_deg": ("number", "longitude, degrees"),
                "height_m": ("number", "ellipsoidal height, m"),
            },
        ),
    ),
}


JSON_SCHEMAS["/gradient"] = (
    "gravsurvey.GravityGradient",
    _json_schema(
        "gravsurvey.GravityGradient",
        "gravitation gradient tensor d g_i / d x_j on the instrument triad",
        {
            "time_ns": ("integer", _T_DESC),
            "gradient_t_eotvos": ("vec6", "components xx, xy, xz, yy, yz, zz, Eotvos (1e-9 1/s^2), triad"),
        },
    ),
)


def _json_gradient(t, g) -> list[bytes]:
    fmt = '{{"time_ns":{},"gradient_t_eotvos":[{},{},{},{},{},{}]}}'.format
    cols = [_ints(t)] + [_reprs(g[:, j]) for j in range(6)]
    return [s.encode("ascii") for s in map(fmt, *cols)]


def _blocked(n: int, make) -> Iterable:
    """Concatenation of ``make(lo, hi)`` over consecutive blocks of ``_BLOCK`` samples of ``n``."""
    for lo in range(0, n, _BLOCK):
        yield from make(lo, min(n, lo + _BLOCK))


def _json_imu(t, f, w) -> list[bytes]:
    fmt = '{{"time_ns":{},"specific_force_t":[{},{},{}],"angular_rate_t":[{},{},{}]}}'.format
    cols = [_ints(t)] + [_reprs(f[:, j]) for j in range(3)] + [_reprs(w[:, j]) for j in range(3)]
    return [s.encode("ascii") for s in map(fmt, *cols)]


def _json_alt(t, h) -> list[bytes]:
    fmt = '{{"time_ns":{},"height_m":{}}}'.format
    return [s.encode("ascii") for s in map(fmt, _ints(t), _reprs(h))]


def _json_gnss(t, lat, lon, h) -> list[bytes]:
    fmt = '{{"time_ns":{},"lat_deg":{},"lon_deg":{},"height_m":{}}}'.format
    return [s.encode("ascii") for s in map(fmt, _ints(t), _reprs(lat), _reprs(lon), _reprs(h))]


# --------------------------------------------------------------------------------------------
# ROS 2 CDR payloads
# --------------------------------------------------------------------------------------------

_SEP = "=" * 80

# ROS 2 (Humble) message definitions, field lines and constants verbatim, comments shortened.
_MSG_TIME = """\
# builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
_MSG_HEADER = """\
# Standard metadata for higher-level stamped data types.
builtin_interfaces/Time stamp
string frame_id
"""
_MSG_QUATERNION = """\
# This represents an orientation in free space in quaternion form.
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""
_MSG_VECTOR3 = """\
# This represents a vector in free space.
float64 x
float64 y
float64 z
"""
_MSG_POINT = """\
# This contains the position of a point in free space
float64 x
float64 y
float64 z
"""
_MSG_IMU = """\
# This is a message to hold data from an IMU (Inertial Measurement Unit)
# Accelerations should be in m/s^2 (not in g's), and rotational velocity should be in rad/sec
# If the covariance of the measurement is known, it should be filled in (if all you know is the
# variance of each measurement, e.g. from the datasheet, just put those along the diagonal)
# A covariance matrix of all zeros will be interpreted as "covariance unknown"
# If you have no estimate for one of the data elements (e.g. your IMU doesn't produce an
# orientation estimate), please set element 0 of the associated covariance matrix to -1
std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance # Row major about x, y, z axes
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance # Row major about x, y, z axes
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance # Row major x, y z
"""
_MSG_POINT_STAMPED = """\
# This represents a Point with reference coordinate frame and timestamp
std_msgs/Header header
Point point
"""
_MSG_NAVSATSTATUS = """\
# Navigation Satellite fix status for any Global Navigation Satellite System.
int8 STATUS_NO_FIX =  -1        # unable to fix position
int8 STATUS_FIX =      0        # unaugmented fix
int8 STATUS_SBAS_FIX = 1        # with satellite-based augmentation
int8 STATUS_GBAS_FIX = 2        # with ground-based augmentation
int8 status
# Bits defining which Global Navigation Satellite System signals were used by the receiver.
uint16 SERVICE_GPS =     1
uint16 SERVICE_GLONASS = 2
uint16 SERVICE_COMPASS = 4      # includes BeiDou.
uint16 SERVICE_GALILEO = 8
uint16 service
"""
_MSG_NAVSATFIX = """\
# Navigation Satellite fix for any Global Navigation Satellite System
# Specified using the WGS 84 reference ellipsoid
std_msgs/Header header
NavSatStatus status
float64 latitude   # degrees, positive north of the equator
float64 longitude  # degrees, positive east of the prime meridian
float64 altitude   # metres above the WGS 84 ellipsoid
float64[9] position_covariance  # m^2, ENU, row-major
uint8 COVARIANCE_TYPE_UNKNOWN = 0
uint8 COVARIANCE_TYPE_APPROXIMATED = 1
uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2
uint8 COVARIANCE_TYPE_KNOWN = 3
uint8 position_covariance_type
"""


def _ros2msg(root: str, deps: Sequence[tuple[str, str]]) -> bytes:
    """Concatenated ros2msg schema text as written by rosbag2 / mcap_ros2."""
    parts = [root.rstrip("\n")]
    for name, text in deps:
        parts.append(f"{_SEP}\nMSG: {name}\n{text.rstrip(chr(10))}")
    return ("\n".join(parts) + "\n").encode("utf-8")


_HDR_DEPS = [("std_msgs/Header", _MSG_HEADER), ("builtin_interfaces/Time", _MSG_TIME)]
ROS2_SCHEMAS = {
    "/imu": (
        "sensor_msgs/msg/Imu",
        _ros2msg(
            _MSG_IMU,
            _HDR_DEPS
            + [
                ("geometry_msgs/Quaternion", _MSG_QUATERNION),
                ("geometry_msgs/Vector3", _MSG_VECTOR3),
            ],
        ),
    ),
    "/altimeter": (
        "geometry_msgs/msg/PointStamped",
        _ros2msg(_MSG_POINT_STAMPED, _HDR_DEPS + [("geometry_msgs/Point", _MSG_POINT)]),
    ),
    "/gnss": (
        "sensor_msgs/msg/NavSatFix",
        _ros2msg(_MSG_NAVSATFIX, _HDR_DEPS + [("sensor_msgs/NavSatStatus", _MSG_NAVSATSTATUS)]),
    ),
}


def cdr_dtype(fields: Sequence[tuple[str, str, tuple]]) -> np.dtype:
    """Structured dtype of one little-endian XCDR1 message, encapsulation header included.

    Parameters
    ----------
    fields : sequence of (name, numpy format, shape)
        Members in serialization order; formats are little-endian primitives (``'<f8'``,
        ``'<u4'``, ``'i1'``, ...) or ``'S<n>'`` for the bytes of a string (NUL included; its
        uint32 length must be its own preceding field).

    Returns
    -------
    numpy.dtype
        Field ``encap`` (4 bytes) then the members, each primitive aligned to its own size
        (max 8) relative to the end of the encapsulation header, as XCDR1 requires; no trailing
        padding.
    """
    names, formats, offsets = ["encap"], [("u1", (4,))], [0]
    pos = 0  # relative to the end of the encapsulation header
    for name, fmt, shape in fields:
        dt = np.dtype(fmt)
        align = 1 if dt.kind == "S" else min(dt.itemsize, 8)
        pos = -(-pos // align) * align
        names.append(name)
        formats.append((dt, shape) if shape else dt)
        offsets.append(4 + pos)
        pos += dt.itemsize * int(np.prod(shape, dtype=np.int64))
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": 4 + pos})


def _header_fields(frame_id: str) -> list[tuple[str, str, tuple]]:
    n = len(frame_id.encode("utf-8")) + 1
    return [("sec", "<i4", ()), ("nanosec", "<u4", ()), ("frame_len", "<u4", ()), ("frame_id", f"S{n}", ())]


def _cdr_records(dtype: np.dtype, t_ns: np.ndarray, frame_id: str) -> np.ndarray:
    """Zeroed records with encapsulation header (CDR_LE, options 0) and std_msgs/Header filled."""
    rec = np.zeros(t_ns.size, dtype=dtype)
    rec["encap"] = (0, 1, 0, 0)
    sec, nsec = ros2_time(t_ns)
    rec["sec"] = sec
    rec["nanosec"] = nsec
    fid = frame_id.encode("utf-8")
    rec["frame_len"] = len(fid) + 1
    rec["frame_id"] = fid  # 'S<n>' pads the final NUL
    return rec


def ros2_time(t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split integer Unix ns into ROS 2 ``builtin_interfaces/Time`` (sec int32, nanosec uint32).

    Parameters
    ----------
    t_ns : ndarray of int64, shape (n,)
        ns since the Unix epoch, 0 <= t_ns < 2**31 s.

    Returns
    -------
    sec : ndarray of int32, shape (n,)
    nanosec : ndarray of uint32, shape (n,)
        ``t_ns == sec * 10**9 + nanosec`` with ``0 <= nanosec < 10**9``.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    sec, nsec = np.divmod(t, _NS)
    return sec.astype(np.int32), nsec.astype(np.uint32)


IMU_CDR_DTYPE = cdr_dtype(
    _header_fields(FRAME_IMU)
    + [
        ("orientation", "<f8", (4,)),
        ("orientation_covariance", "<f8", (9,)),
        ("angular_velocity", "<f8", (3,)),
        ("angular_velocity_covariance", "<f8", (9,)),
        ("linear_acceleration", "<f8", (3,)),
        ("linear_acceleration_covariance", "<f8", (9,)),
    ]
)
POINT_STAMPED_CDR_DTYPE = cdr_dtype(_header_fields(FRAME_ALTIMETER) + [("point", "<f8", (3,))])
NAVSATFIX_CDR_DTYPE = cdr_dtype(
    _header_fields(FRAME_GNSS)
    + [
        ("status", "i1", ()),
        ("service", "<u2", ()),
        ("latitude", "<f8", ()),
        ("longitude", "<f8", ()),
        ("altitude", "<f8", ()),
        ("position_covariance", "<f8", (9,)),
        ("position_covariance_type", "u1", ()),
    ]
)


def _split(rec: np.ndarray) -> list[bytes]:
    buf = rec.tobytes()
    size = rec.dtype.itemsize
    return [buf[k : k + size] for k in range(0, len(buf), size)]


def _cdr_imu(t, f, w, accel_sigma, gyro_sigma) -> list[bytes]:
    rec = _cdr_records(IMU_CDR_DTYPE, t, FRAME_IMU)
    rec["orientation"] = (0.0, 0.0, 0.0, 1.0)
    rec["orientation_covariance"][:, 0] = -1.0  # REP-145: no orientation estimate
    rec["angular_velocity"] = w
    rec["angular_velocity_covariance"] = np.diag(gyro_sigma**2).ravel()
    rec["linear_acceleration"] = f
    rec["linear_acceleration_covariance"] = np.diag(accel_sigma**2).ravel()
    return _split(rec)


def _cdr_alt(t, h) -> list[bytes]:
    rec = _cdr_records(POINT_STAMPED_CDR_DTYPE, t, FRAME_ALTIMETER)
    rec["point"][:, 2] = h
    return _split(rec)


def _cdr_gnss(t, lat, lon, h, sigma) -> list[bytes]:
    rec = _cdr_records(NAVSATFIX_CDR_DTYPE, t, FRAME_GNSS)
    rec["status"] = 0  # STATUS_FIX
    rec["service"] = 1  # SERVICE_GPS
    rec["latitude"] = lat
    rec["longitude"] = lon
    rec["altitude"] = h
    rec["position_covariance"] = np.diag(sigma**2).ravel()
    rec["position_covariance_type"] = 2  # COVARIANCE_TYPE_DIAGONAL_KNOWN
    return _split(rec)


# --------------------------------------------------------------------------------------------
# MCAP
# --------------------------------------------------------------------------------------------


def _metadata(flight_name: str, c: _Checked, comments: Sequence[str]) -> dict[str, str]:
    md = {
        "flight": flight_name,
        "start_unix_ns": str(c.start_unix_ns),
        "start_utc": utc_iso(c.start_unix_ns),
        "writer": _LIBRARY,
    }
    if comments:
        md["comments"] = "\n".join(comments)
    return md


def _write_mcap(
    fh,
    profile: str,
    encoding: str,
    schema_encoding: str,
    schemas: dict,
    topics: list[tuple[str, np.ndarray, list[bytes]]],
    metadata: dict,
) -> None:
    """Write one MCAP file: messages of all topics interleaved in time order (ties: topic order)."""
    w = Writer(
        fh,
        chunk_size=_CHUNK_SIZE,
        compression=CompressionType.ZSTD,
        index_types=IndexType.ALL,
        use_statistics=True,
        use_summary_offsets=True,
    )
    w.start(profile=profile, library=_LIBRARY)
    w.add_metadata("gravsurvey", metadata)
    channel_ids = []
    for topic, _, _ in topics:
        name, data = schemas[topic]
        sid = w.register_schema(name=name, encoding=schema_encoding, data=data)
        channel_ids.append(w.register_channel(topic=topic, message_encoding=encoding, schema_id=sid))

    # Within a topic the order is the sample order, so each topic's payloads are consumed from
    # an iterator; the merged order only says which topic comes next.
    times = np.concatenate([t for _, t, _ in topics])
    which = np.concatenate([np.full(t.size, j, dtype=np.int8) for j, (_, t, _) in enumerate(topics)])
    index = np.concatenate([np.arange(t.size, dtype=np.int64) for _, t, _ in topics])
    order = np.argsort(times, kind="stable")
    nexts = [iter(p).__next__ for _, _, p in topics]
    add = w.add_message
    for lo in range(0, order.size, 4 * _BLOCK):
        sel = order[lo : lo + 4 * _BLOCK]
        for t, j, k in zip(times[sel].tolist(), which[sel].tolist(), index[sel].tolist()):
            add(channel_ids[j], t, nexts[j](), t, k)
    w.finish()


def _mcap_json_topics(c: _Checked):
    """(topic, times, payload iterator) per topic, JSON encoding."""
    t, f, w, ta, h = c.imu_t, c.f_t, c.w_t, c.alt_t, c.alt_h
    topics = [
        ("/imu", t, _blocked(t.size, lambda a, b: _json_imu(t[a:b], f[a:b], w[a:b]))),
        ("/altimeter", ta, _blocked(ta.size, lambda a, b: _json_alt(ta[a:b], h[a:b]))),
    ]
    if c.gnss_t is not None:
        tg, lat, lon, hg = c.gnss_t, c.lat, c.lon, c.gnss_h
        topics.append(("/gnss", tg, _blocked(tg.size, lambda a, b: _json_gnss(tg[a:b], lat[a:b], lon[a:b], hg[a:b]))))
    if c.grad_t is not None:
        tq, gq = c.grad_t, c.grad
        topics.append(("/gradient", tq, _blocked(tq.size, lambda a, b: _json_gradient(tq[a:b], gq[a:b]))))
    return topics


def _mcap_ros2_topics(c: _Checked):
    """(topic, times, payload iterator) per topic, ROS 2 CDR encoding."""
    t, f, w, ta, h = c.imu_t, c.f_t, c.w_t, c.alt_t, c.alt_h
    sa, sg, sn = c.accel_sigma, c.gyro_sigma, c.gnss_sigma
    topics = [
        ("/imu", t, _blocked(t.size, lambda a, b: _cdr_imu(t[a:b], f[a:b], w[a:b], sa, sg))),
        ("/altimeter", ta, _blocked(ta.size, lambda a, b: _cdr_alt(ta[a:b], h[a:b]))),
    ]
    if c.gnss_t is not None:
        tg, lat, lon, hg = c.gnss_t, c.lat, c.lon, c.gnss_h
        topics.append(
            ("/gnss", tg, _blocked(tg.size, lambda a, b: _cdr_gnss(tg[a:b], lat[a:b], lon[a:b], hg[a:b], sn)))
        )
    return topics


# --------------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------------


def _csv_bytes(header_comments: list[str], columns: list[str], cells: list[list[str]]) -> bytes:
    lines = header_comments + [",".join(columns)]
    lines.extend(map(",".join, zip(*cells)))
    lines.append("")
    return "\n".join(lines).encode("utf-8")


def _csv_stream(header_comments: list[str], columns: list[str], n: int, cells) -> Iterable[bytes]:
    """Header lines, then rows block by block; ``cells(lo, hi)`` gives the column strings."""
    yield ("\n".join(header_comments + [",".join(columns)]) + "\n").encode("utf-8")
    for lo in range(0, n, _BLOCK):
        rows = map(",".join, zip(*cells(lo, min(n, lo + _BLOCK))))
        yield ("\n".join(rows) + "\n").encode("ascii")


def _csv_comments(flight: str, channel: str, c: _Checked, what: list[str], comments) -> list[str]:
    return [
        f"# gravsurvey simulated sensor log: flight {flight}, channel {channel}",
        f"# start_utc {utc_iso(c.start_unix_ns)} (start_unix_ns {c.start_unix_ns})",
        "# time_ns: measurement time, integer ns since the Unix epoch (UTC)",
        *("# " + s for s in what),
        *_comment_lines(comments),
    ]


def _csv_files(flight: str, c: _Checked, comments) -> list[tuple[str, Iterable[bytes]]]:
    t, f, w, ta, h = c.imu_t, c.f_t, c.w_t, c.alt_t, c.alt_h
    imu = _csv_stream(
        _csv_comments(
            flight,
            "imu",
            c,
            [
                "f*_mps2: specific force F = a_inertial - G on the instrument triad, m/s^2",
                "w*_radps: absolute angular rate of the triad, on the triad, rad/s",
            ],
            comments,
        ),
        ["time_ns", "fx_mps2", "fy_mps2", "fz_mps2", "wx_radps", "wy_radps", "wz_radps"],
        t.size,
        lambda a, b: [_ints(t[a:b])] + [_reprs(f[a:b, j]) for j in range(3)] + [_reprs(w[a:b, j]) for j in range(3)],
    )
    alt = _csv_stream(
        _csv_comments(flight, "altimeter", c, ["height_m: ellipsoidal height, m"], comments),
        ["time_ns", "height_m"],
        ta.size,
        lambda a, b: [_ints(ta[a:b]), _reprs(h[a:b])],
    )
    out = [("imu.csv", imu), ("altimeter.csv", alt)]
    if c.gnss_t is not None:
        tg, lat, lon, hg = c.gnss_t, c.lat, c.lon, c.gnss_h
        gnss = _csv_stream(
            _csv_comments(
                flight,
                "gnss",
                c,
                ["lat_deg, lon_deg: WGS84 geodetic latitude, longitude, degrees; height_m: ellipsoidal height, m"],
                comments,
            ),
            ["time_ns", "lat_deg", "lon_deg", "height_m"],
            tg.size,
            lambda a, b: [_ints(tg[a:b]), _reprs(lat[a:b]), _reprs(lon[a:b]), _reprs(hg[a:b])],
        )
        out.append(("gnss.csv", gnss))
    if c.grad_t is not None:
        tq, gq = c.grad_t, c.grad
        names = ("txx", "txy", "txz", "tyy", "tyz", "tzz")
        grad = _csv_stream(
            _csv_comments(
                flight,
                "gradient",
                c,
                ["t??_eotvos: gravitation gradient tensor d g_i / d x_j on the instrument triad, Eotvos (1e-9 1/s^2)"],
                comments,
            ),
            ["time_ns"] + [f"{q}_eotvos" for q in names],
            tq.size,
            lambda a, b: [_ints(tq[a:b])] + [_reprs(gq[a:b, j]) for j in range(6)],
        )
        out.append(("gradient.csv", grad))
    return out


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def write_flight_logs(
    out_dir: str | os.PathLike,
    flight_name: str,
    formats: Iterable[str],
    logs: SensorLogs,
    comments: Iterable[str] = (),
) -> list[Path]:
    """Write one flight's sensor logs in the requested formats (docs/formats.md).

    Parameters
    ----------
    out_dir : path
        Destination directory (created if missing).
    flight_name : str
        Flight name; the MCAP files are ``<flight_name>_json.mcap`` and ``<flight_name>_ros2.mcap``.
    formats : iterable of str
        Subset of ``{"mcap_json", "mcap_ros2", "csv"}``; ``"csv"`` writes ``imu.csv``,
        ``altimeter.csv`` and (with GNSS) ``gnss.csv``.
    logs : SensorLogs
        The samples.  Checked first: integer, strictly increasing, non-negative ns stamps not
        before ``start_unix_ns``; finite floats of the right shapes.
    comments : iterable of str
        Free text written as ``#`` lines at the top of each CSV and in the MCAP metadata record.

    Returns
    -------
    list of pathlib.Path
        The files written, in the order mcap_json, mcap_ros2, csv.

    Raises
    ------
    ConfigError
        Unknown format or unusable flight name.
    DataError
        Samples violate the contract above (message names the channel and what was expected).

    Notes
    -----
    All files are written to temporary files in ``out_dir`` and moved into place together at the
    end; on any error none of the targets is created or changed.  Output is byte-identical for
    identical inputs.
    """
    wanted = _check_formats(formats)
    flight_name = _check_flight_name(flight_name)
    c = _check_logs(logs, need_int32_seconds="mcap_ros2" in wanted)
    comments = list(comments) if not isinstance(comments, str) else [comments]
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DataError(f"{out_dir}: cannot create the output directory ({e.strerror})") from e

    written: list[Path] = []
    md = _metadata(flight_name, c, [str(x) for x in comments])
    try:
        with _AtomicFiles() as files:
            if "mcap_json" in wanted:
                target = out_dir / f"{flight_name}_json.mcap"
                with files.open(target) as fh:
                    _write_mcap(fh, "", "json", "jsonschema", JSON_SCHEMAS, _mcap_json_topics(c), md)
                    fh.flush()
                    os.fsync(fh.fileno())
                written.append(target)
            if "mcap_ros2" in wanted:
                target = out_dir / f"{flight_name}_ros2.mcap"
                with files.open(target) as fh:
                    _write_mcap(fh, "ros2", "cdr", "ros2msg", ROS2_SCHEMAS, _mcap_ros2_topics(c), md)
                    fh.flush()
                    os.fsync(fh.fileno())
                written.append(target)
            if "csv" in wanted:
                for name, chunks in _csv_files(flight_name, c, comments):
                    target = out_dir / name
                    _write_bytes_atomic(files, target, chunks)
                    written.append(target)
    except OSError as e:
        raise DataError(f"{out_dir}: writing flight {flight_name} logs failed ({e})") from e
    return written


def _truth_column(name: str, value, n: int | None, path: Path) -> list[str]:
    a = np.asarray(value)
    if a.ndim != 1:
        raise DataError(f"{path}: truth column {name!r} must be 1-D, got shape {a.shape}")
    if n is not None and a.size != n:
        raise DataError(f"{path}: truth column {name!r} has {a.size} rows, expected {n}")
    if name == "time_ns":
        if a.dtype.kind not in "iu":
            raise DataError(f"{path}: truth column 'time_ns' must be integer Unix ns, got {a.dtype}")
        return _ints(a.astype(np.int64))
    if a.dtype.kind in "iu":
        return _ints(a.astype(np.int64))
    if a.dtype.kind == "f":
        a = a.astype(np.float64, copy=False)
        if not np.all(np.isfinite(a)):
            k = int(np.flatnonzero(~np.isfinite(a))[0])
            raise DataError(f"{path}: truth column {name!r} not finite at row {k}")
        return _reprs(a)
    if a.dtype.kind in "UO":
        s = [str(v) for v in a.tolist()]
        for k, v in enumerate(s):
            if not v or any(ch in v for ch in ',"\n\r#') or v != v.strip():
                raise DataError(
                    f"{path}: truth column {name!r} row {k}: {v!r} is not a plain CSV token "
                    "(non-empty, no comma, quote, '#', newline or edge spaces)"
                )
        return s
    raise DataError(f"{path}: truth column {name!r} has unsupported dtype {a.dtype}")


def write_truth_csv(
    path: str | os.PathLike,
    columns: Mapping[str, np.ndarray],
    comments: Iterable[str] = (),
) -> Path:
    """Write a flight's ``truth.csv`` (docs/formats.md), atomically.

    Parameters
    ----------
    path : path
        Target file (its directory is created if missing).
    columns : mapping of str to ndarray, each shape (n,)
        Must contain every name in :data:`TRUTH_COLUMNS` (``time_ns`` integer Unix ns, ``line``
        strings, the rest floats in the units their names say); they are written in that order,
        followed by any extra columns in mapping order.  Floats are written with ``repr``
        (exact float64 round trip); they must be finite.
    comments : iterable of str
        Written as ``#`` lines above the header row.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    DataError
        A column is missing, of the wrong kind or length, or not representable.
    """
    path = Path(path)
    missing = [c for c in TRUTH_COLUMNS if c not in columns]
    if missing:
        raise DataError(f"{path}: truth columns missing: {', '.join(missing)}")
    names = list(TRUTH_COLUMNS) + [c for c in columns if c not in TRUTH_COLUMNS]
    for c in names:
        if not isinstance(c, str) or not c or any(ch in c for ch in ',"\n\r# '):
            raise DataError(f"{path}: truth column name {c!r} is not a plain CSV token")
    n = np.asarray(columns["time_ns"]).size
    cells = [_truth_column(c, columns[c], n, path) for c in names]
    header = [
        "# gravsurvey simulated flight truth",
        "# time_ns: Unix ns (UTC); line: flight-plan segment; lat_deg, lon_deg, height_m: WGS84 geodetic;",
        "# v*_mps: velocity relative to the Earth, ENU; roll/pitch/heading_deg: body attitude w.r.t. ENU;",
        "# disturbance_mgal = -(anomalous gravitation . Up); anomaly_*_mgal: anomalous gravitation, ENU",
        "# dg_north_mgal, dg_east_mgal: horizontal disturbance g_true - gamma (= anomaly_n, anomaly_e)",
        *_comment_lines(comments),
    ]
    data = _csv_bytes(header, names, cells)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with _AtomicFiles() as files:
            _write_bytes_atomic(files, path, [data])
    except OSError as e:
        raise DataError(f"{path}: writing truth failed ({e})") from e
    return path
