"""The 13 JSON tables of a nuScenes version folder (``v1.0-trainval/``, ``v1.0-mini/``, ...),
read strictly: :func:`read_tables` -> :class:`Tables`.

Each table is a JSON list of objects with a ``token``. The fields a reader uses (:data:`SCHEMA`,
from nuScenes' published schema) must be present with the documented type; anything else about a
record is kept as it is. A malformed table is one line naming the file, the record (its index and
token) and the field: ``v1.0-mini/ego_pose.json: record 12 (token 5ace...): field 'rotation':
expected 4 numbers``. Files are read under the project's reading policy
(:func:`scenes.utils.textfile.read_json_file`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from scenes.utils.errors import RootError
from scenes.utils.textfile import read_json_file

__all__ = ["SCHEMA", "TABLES", "NuScenesError", "Tables", "read_tables", "version_folder"]

TABLES: tuple[str, ...] = (
    "category", "attribute", "visibility", "instance", "sensor", "calibrated_sensor", "ego_pose",
    "log", "scene", "sample", "sample_data", "sample_annotation", "map",
)  # fmt: skip
"""The 13 tables of nuScenes v1.0, ``<name>.json`` each."""


class NuScenesError(RootError):
    """A nuScenes root or table is malformed; the message names the file, record and field."""


def _number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _vector(n: int) -> tuple[Callable[[object], bool], str]:
    return (
        lambda v: isinstance(v, list) and len(v) == n and all(_number(x) for x in v),
        f"{n} numbers",
    )


_TOKEN = (lambda v: isinstance(v, str), "a string")
_TEXT = _TOKEN
_LINK = (lambda v: isinstance(v, str), "a token string ('' for none)")
_INT = (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer")
_BOOL = (lambda v: isinstance(v, bool), "true or false")
_TOKENS = (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a token list")
_INTRINSIC = (
    lambda v: (
        isinstance(v, list) and (v == [] or (len(v) == 3 and all(_vector(3)[0](row) for row in v)))
    ),
    "a 3 x 3 matrix or []",
)
_SIZE = (lambda v: _vector(3)[0](v) and all(x > 0 for x in v), "3 positive numbers (w, l, h)")
_QUATERNION = (
    lambda v: _vector(4)[0](v) and sum(x * x for x in v) > 1e-12,
    "4 numbers (w, x, y, z), not all 0",
)

SCHEMA: dict[str, dict[str, tuple[Callable[[object], bool], str]]] = {
    "category": {"name": _TEXT},
    "attribute": {"name": _TEXT},
    "visibility": {"level": _TEXT},
    "instance": {"category_token": _LINK},
    "sensor": {"channel": _TEXT, "modality": _TEXT},
    "calibrated_sensor": {
        "sensor_token": _LINK,
        "translation": _vector(3),
        "rotation": _QUATERNION,
        "camera_intrinsic": _INTRINSIC,
    },
    "ego_pose": {"timestamp": _INT, "translation": _vector(3), "rotation": _QUATERNION},
    "log": {"location": _TEXT},
    "scene": {
        "name": _TEXT,
        "description": _TEXT,
        "log_token": _LINK,
        "first_sample_token": _LINK,
    },
    "sample": {"timestamp": _INT, "scene_token": _LINK, "prev": _LINK, "next": _LINK},
    "sample_data": {
        "sample_token": _LINK,
        "ego_pose_token": _LINK,
        "calibrated_sensor_token": _LINK,
        "timestamp": _INT,
        "is_key_frame": _BOOL,
        "filename": _TEXT,
        "prev": _LINK,
        "next": _LINK,
    },
    "sample_annotation": {
        "sample_token": _LINK,
        "instance_token": _LINK,
        "attribute_tokens": _TOKENS,
        "translation": _vector(3),
        "size": _SIZE,
        "rotation": _QUATERNION,
    },
    "map": {"log_tokens": _TOKENS, "filename": _TEXT},
}
"""Table -> field -> (check, what it must be): the fields the reader uses."""


@dataclass(frozen=True)
class Tables:
    """The tables of one version folder, each ``token -> record`` in file order.

    Attributes:
        folder: The version folder.
        records: Table name -> ``{token: record}``.
    """

    folder: Path
    records: dict[str, dict[str, dict]]

    def get(self, table: str, token: str, by: str = "") -> dict:
        """The record ``token`` of ``table``.

        Raises:
            NuScenesError: no such record (names the table and, given ``by``, who refers to it).
        """
        try:
            return self.records[table][token]
        except KeyError:
            who = f" (referred to by {by})" if by else ""
            raise NuScenesError(
                f"{self.folder / (table + '.json')}: no record with token {token!r}{who}"
            ) from None


def version_folder(root: Path, version: str | None) -> Path:
    """The version folder of a root: ``root/version``, or the one ``v1.0-*`` folder present.

    Raises:
        NuScenesError: the folder is missing, or ``version`` is None and there are none or several
            (the message lists the folders found and says to keep one: no command takes a
            version).
    """
    if version is not None:
        folder = root / version
        if not folder.is_dir():
            raise NuScenesError(f"{folder}: no such nuScenes version folder")
        return folder
    found = sorted(p for p in root.glob("v1.0-*") if p.is_dir())
    if not found:
        raise NuScenesError(
            f"{root}: no nuScenes version folders (v1.0-*); is this a nuScenes root?"
        )
    if len(found) > 1:
        names = ", ".join(p.name for p in found)
        raise NuScenesError(
            f"{root}: {len(found)} ({names}) nuScenes version folders (v1.0-*), and a root is "
            f"read with exactly one: keep the one to use in {root} and move the others out (each "
            "release in a root of its own)"
        )
    return found[0]


def read_tables(folder: str | Path) -> Tables:
    """Read and check the 13 tables of a version folder.

    Raises:
        NuScenesError: a missing table, a table that is not a list of objects, a record without a
            token or with a token seen before, or a field missing or of the wrong type (one line
            naming the file, record index, token and field).
    """
    folder = Path(folder)
    records: dict[str, dict[str, dict]] = {}
    for table in TABLES:
        path = folder / f"{table}.json"
        if not path.is_file():
            raise NuScenesError(f"{path}: missing table ({table!r} is one of nuScenes' 13)")
        data = read_json_file(path, f"nuScenes {table} table", NuScenesError)
        if not isinstance(data, list):
            raise NuScenesError(f"{path}: expected a JSON list of records")
        schema = SCHEMA[table]
        by_token: dict[str, dict] = {}
        for i, rec in enumerate(data):
            if not isinstance(rec, dict):
                raise NuScenesError(f"{path}: record {i}: expected a JSON object")
            token = rec.get("token")
            if not isinstance(token, str) or not token:
                raise NuScenesError(f"{path}: record {i}: field 'token': missing or not a string")
            if token in by_token:
                raise NuScenesError(f"{path}: record {i} (token {token}): token seen before")
            for name, (check, what) in schema.items():
                if name not in rec:
                    raise NuScenesError(
                        f"{path}: record {i} (token {token}): field {name!r} is missing"
                    )
                if not check(rec[name]):
                    raise NuScenesError(
                        f"{path}: record {i} (token {token}): field {name!r}: expected {what}, "
                        f"got {str(rec[name])[:60]}"
                    )
            by_token[token] = rec
        records[table] = by_token
    return Tables(folder, records)
