"""nuScenes sensor files, written and read: LIDAR_TOP ``.pcd.bin`` and the radars' PCD v0.7.

LiDAR (``samples/LIDAR_TOP/*.pcd.bin``): float32 x 5 per point, ``x, y, z, intensity, ring
index``, in the LIDAR_TOP frame (x right, y forward, z up). A file whose size is not a multiple
of 20 bytes, or with a NaN or infinite value in any channel of any point, is refused naming the
file, the first such point and its channel.

Radar (``samples/RADAR_*/*.pcd``): PCD v0.7, ``DATA binary``, the 18 fields of
:data:`RADAR_FIELDS` with the sizes and types of :data:`RADAR_SIZES` / :data:`RADAR_TYPES`
(little-endian, packed), each radar in its own frame (x forward of that radar). An empty sweep is
one point whose float fields are NaN (the devkit reads it as no point). The official devkit's
reader (1.2.0) asserts that bytes remain after every field it reads, so :func:`write_radar` ends
the file with one byte after the last point (:data:`TRAILER`), as the release's files do; the
reader here accepts a file with or without it.

The radar reader is strict, naming the file: the header's lines are the release's, in its order
(:data:`_HEADER_ORDER`, as the devkit reads them by place), ``VERSION`` 0.7, ``VIEWPOINT`` the
identity (another would move every point); ``WIDTH`` and ``POINTS`` must be one whole number
>= 0 each and agree (``HEIGHT`` is 1, ``COUNT`` 1 per field), the file must hold those points and
not a whole point more, and every float field of every point must be finite, except the one
point of an empty sweep (a lone point whose ``x``, ``y`` or ``z`` is NaN).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes.utils.durable import atomic_write_bytes

__all__ = [
    "LIDAR_COLUMNS",
    "LIDAR_FIELDS",
    "RADAR_FIELDS",
    "RADAR_SIZES",
    "RADAR_TYPES",
    "TRAILER",
    "SensorFileError",
    "empty_radar",
    "radar_dtype",
    "read_lidar",
    "read_radar",
    "write_lidar",
    "write_radar",
]

LIDAR_COLUMNS = 5
"""float32 values per LiDAR point: x, y, z, intensity, ring index."""
LIDAR_FIELDS: tuple[str, ...] = ("x", "y", "z", "intensity", "ring")
"""The names of a LiDAR point's :data:`LIDAR_COLUMNS` values, in file order (messages name them)."""
RADAR_FIELDS: tuple[str, ...] = (
    "x", "y", "z", "dyn_prop", "id", "rcs", "vx", "vy", "vx_comp", "vy_comp",
    "is_quality_valid", "ambig_state", "x_rms", "y_rms", "invalid_state", "pdh0", "vx_rms",
    "vy_rms",
)  # fmt: skip
"""The 18 fields of a nuScenes radar PCD, in file order."""
RADAR_SIZES: tuple[int, ...] = (4, 4, 4, 1, 2, 4, 4, 4, 4, 4, 1, 1, 1, 1, 1, 1, 1, 1)
"""Bytes per field."""
RADAR_TYPES: tuple[str, ...] = ("F", "F", "F", "I", "I", "F", "F", "F", "F", "F") + ("I",) * 8
"""PCD type per field: F float, I signed integer."""
TRAILER = b"\x00"
"""The byte :func:`write_radar` puts after the last point (see the module docstring)."""
_HEADER_ORDER = (
    "VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA",
)  # fmt: skip
"""The header's lines after the comment, in the order the release and the devkit have them."""
IDENTITY_VIEWPOINT = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
"""The only ``VIEWPOINT`` read (tx ty tz qw qx qy qz): the points are in the radar's frame."""


class SensorFileError(ValueError):
    """A sensor file is malformed; the message names the file."""


def radar_dtype() -> np.dtype:
    """The packed little-endian record of one radar point (:data:`RADAR_FIELDS`)."""
    kinds = {("F", 4): "<f4", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4"}
    return np.dtype(
        [(n, kinds[(t, s)]) for n, t, s in zip(RADAR_FIELDS, RADAR_TYPES, RADAR_SIZES, strict=True)]
    )


def read_lidar(path: str | Path) -> np.ndarray:
    """A LIDAR_TOP file as ``(N, 5)`` float32 ``x, y, z, intensity, ring`` (LIDAR_TOP frame).

    Raises:
        SensorFileError: missing, a size not a multiple of 20 bytes, or a NaN or infinite value
            in any channel (names the first such point and channel).
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise SensorFileError(f"{path}: cannot read the LiDAR file ({exc.strerror})") from exc
    if len(raw) % (4 * LIDAR_COLUMNS):
        raise SensorFileError(
            f"{path}: {len(raw)} bytes is not a whole number of {LIDAR_COLUMNS}-float32 points"
        )
    points = np.frombuffer(raw, dtype="<f4").reshape(-1, LIDAR_COLUMNS).astype(np.float32)
    _check_finite(path, ~np.isfinite(points), LIDAR_FIELDS)
    return points


def _check_finite(path: Path, bad: np.ndarray, names: tuple[str, ...]) -> None:
    """Raise :class:`SensorFileError` naming the first point (row of ``bad``, ``(N, len(names))``
    bool: True where a value is NaN or infinite) with a bad value, and that value's channel."""
    rows = np.flatnonzero(bad.any(axis=1))
    if len(rows):
        row = int(rows[0])
        name = names[int(np.argmax(bad[row]))]
        raise SensorFileError(
            f"{path}: point {row} has a NaN or infinite {name!r}; bad points: {len(rows)} of "
            f"{len(bad)}"
        )


def write_lidar(path: str | Path, points: np.ndarray) -> None:
    """Write ``(N, 5)`` ``x, y, z, intensity, ring`` (LIDAR_TOP frame) as float32, atomically."""
    arr = np.asarray(points, dtype="<f4")
    if arr.ndim != 2 or arr.shape[1] != LIDAR_COLUMNS:
        raise ValueError(f"{path}: LiDAR points must be (N, {LIDAR_COLUMNS}), got {arr.shape}")
    atomic_write_bytes(Path(path), np.ascontiguousarray(arr).tobytes())


def empty_radar() -> np.ndarray:
    """The one-point record array of an empty sweep: float fields NaN, integer fields 0."""
    rec = np.zeros(1, dtype=radar_dtype())
    for name, kind in zip(RADAR_FIELDS, RADAR_TYPES, strict=True):
        if kind == "F":
            rec[name] = np.nan
    return rec


def _header(count: int) -> bytes:
    lines = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        "FIELDS " + " ".join(RADAR_FIELDS),
        "SIZE " + " ".join(str(s) for s in RADAR_SIZES),
        "TYPE " + " ".join(RADAR_TYPES),
        "COUNT " + " ".join("1" for _ in RADAR_FIELDS),
        f"WIDTH {count}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {count}",
        "DATA binary",
    ]
    return ("\n".join(lines) + "\n").encode("ascii")


def write_radar(path: str | Path, points: np.ndarray) -> None:
    """Write a radar sweep (a record array of :func:`radar_dtype`, the radar's own frame) as PCD
    v0.7 binary, atomically; no point = one NaN point (:func:`empty_radar`)."""
    rec = np.asarray(points)
    if rec.dtype != radar_dtype():
        raise ValueError(f"{path}: radar points must be a record array of radar_dtype()")
    if len(rec) == 0:
        rec = empty_radar()
    atomic_write_bytes(Path(path), _header(len(rec)) + rec.tobytes() + TRAILER)


def read_radar(path: str | Path) -> np.ndarray:
    """A radar PCD as a record array of :func:`radar_dtype` (the radar's frame, every point: no
    filter); an empty sweep (a first point with NaN) gives no point.

    Raises:
        SensorFileError: missing, a header other than the 18-field binary layout (a line
            missing, repeated, unknown or out of order: names the line; a ``VERSION`` other
            than 0.7, a ``VIEWPOINT`` other than the identity), a ``WIDTH`` or ``POINTS`` that is not one whole number >= 0 or that disagree,
            fewer bytes than its points need or a whole point more, or a NaN or infinite float
            field (names the first such point and field) outside an empty sweep.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise SensorFileError(f"{path}: cannot read the radar file ({exc.strerror})") from exc
    offset, header = 0, {}
    for lineno in range(1, len(_HEADER_ORDER) + 2):
        end = raw.find(b"\n", offset)
        if end < 0:
            raise SensorFileError(f"{path}: the PCD header ends before its DATA line")
        try:
            line = raw[offset:end].decode("ascii").strip()
        except UnicodeDecodeError as exc:
            raise SensorFileError(f"{path}:{lineno}: the PCD header is not ASCII") from exc
        offset = end + 1
        if lineno == 1:
            if not line.startswith("#"):
                raise SensorFileError(f"{path}:1: expected the PCD comment line, got {line[:40]!r}")
            continue
        key, *value = line.split() or [""]
        want = _HEADER_ORDER[lineno - 2]
        if key != want:  # a missing, repeated, unknown or moved line (the devkit reads by place)
            raise SensorFileError(
                f"{path}:{lineno}: expected the PCD {want} line (the header's lines are "
                f"{' '.join(_HEADER_ORDER)}, in that order), got {line[:40]!r}"
            )
        header[key] = value
    if header["VERSION"] not in (["0.7"], [".7"]):
        raise SensorFileError(
            f"{path}: PCD VERSION is {' '.join(header['VERSION'])!r}, expected '0.7'"
        )
    _check_viewpoint(path, header["VIEWPOINT"])
    expected = {
        "FIELDS": list(RADAR_FIELDS),
        "SIZE": [str(s) for s in RADAR_SIZES],
        "TYPE": list(RADAR_TYPES),
        "COUNT": ["1"] * len(RADAR_FIELDS),
        "DATA": ["binary"],
        "HEIGHT": ["1"],
    }
    for key, want in expected.items():
        if header.get(key) != want:
            raise SensorFileError(
                f"{path}: PCD {key} is {' '.join(header.get(key, ['(missing)']))!r}, "
                f"expected {' '.join(want)!r}"
            )
    count = _header_count(path, header, "WIDTH")
    points = _header_count(path, header, "POINTS")
    if points != count:
        raise SensorFileError(
            f"{path}: PCD POINTS is {points} but WIDTH x HEIGHT is {count}; they must agree"
        )
    dtype = radar_dtype()
    need, have = count * dtype.itemsize, len(raw) - offset
    if have < need:
        raise SensorFileError(f"{path}: {count} points need {need} bytes, the file has {have}")
    if have - need >= dtype.itemsize:
        raise SensorFileError(
            f"{path}: the file holds {have} bytes of points, {have - need} more than the {count} "
            f"points of its header need ({dtype.itemsize} bytes each): WIDTH / POINTS are wrong"
        )
    rec = np.frombuffer(raw, dtype=dtype, count=count, offset=offset).copy()
    if count == 1 and np.isnan([rec[0][n] for n in RADAR_FIELDS[:3]]).any():
        return rec[:0]  # the one point of an empty sweep
    floats = tuple(n for n, t in zip(RADAR_FIELDS, RADAR_TYPES, strict=True) if t == "F")
    _check_finite(path, np.stack([~np.isfinite(rec[n]) for n in floats], axis=1), floats)
    return rec


def _check_viewpoint(path: Path, value: list[str]) -> None:
    """A PCD ``VIEWPOINT`` must be the identity (seven numbers): another one would move every
    point, which the devkit does not do either.

    Raises:
        SensorFileError: not seven numbers, or not the identity (names the file and value).
    """
    try:
        numbers = tuple(float(v) for v in value)
    except ValueError:
        numbers = ()
    if numbers != IDENTITY_VIEWPOINT:
        raise SensorFileError(
            f"{path}: PCD VIEWPOINT is {' '.join(value)!r}, expected '0 0 0 1 0 0 0' (the points "
            "in the radar's own frame)"
        )


def _header_count(path: Path, header: dict[str, list[str]], key: str) -> int:
    """The PCD header's ``key`` (``WIDTH``, ``POINTS``): one whole number >= 0.

    Raises:
        SensorFileError: missing, several values, not a whole number, or negative.
    """
    value = header.get(key)
    if value is None:
        raise SensorFileError(f"{path}: the PCD header has no {key} line")
    text = " ".join(value)
    if len(value) != 1 or not value[0].isascii() or not value[0].isdigit():
        raise SensorFileError(f"{path}: PCD {key} is {text!r}, expected one whole number >= 0")
    return int(value[0])
