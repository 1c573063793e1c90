"""Configs to plain data and back: :func:`to_plain` (dicts, lists, str, int, float, bool) and
:func:`from_plain`, which checks every field against its annotation and raises
:class:`model.config.ConfigError` naming the dotted field (``fusion.agent_size``) of an unknown,
missing or mistyped value (a field added later says in its metadata what its absence meant,
:data:`ABSENT`); :func:`apply_overrides` edits a config by field paths and aliases.

Why not ``dacite`` or ``cattrs``: every error here names the dotted path of the field, also for
an unknown key inside a section and for a value a section's own checks refuse (its
``__post_init__``), which checkpoints' and ``build_model``'s messages rely on; ``dacite`` names no
path for an unknown nested key and passes the sections' own errors through without one.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any, Literal, TypeVar

from model.config.errors import ConfigError

T = TypeVar("T")

ABSENT = "absent"
"""Field metadata key: the value a field takes in plain data written before it existed
(``field(default=True, metadata={ABSENT: False})``); any other missing field is an error."""


def to_plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, tuple | list):
        return [to_plain(v) for v in value]
    return value


def _convert(tp: Any, value: Any, path: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert lists to tuples."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return from_plain(tp, value, path)
    if origin is Literal:
        choices = typing.get_args(tp)
        if value not in choices:
            raise ConfigError(f"config field {path!r}: {value!r} is not one of {choices}", path)
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"config field {path!r}: expected a list, got {value!r}", path)
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(
                f"config field {path!r}: expected {len(args)} values, got {value!r}", path
            )
        return tuple(
            _convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            if arg is type(None) and value is None:
                return None
            try:
                return _convert(arg, value, path)
            except ConfigError:
                continue
        raise ConfigError(f"config field {path!r}: {value!r} matches none of {tp}", path)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config field {path!r}: expected a bool, got {value!r}", path)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config field {path!r}: expected an int, got {value!r}", path)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"config field {path!r}: expected a float, got {value!r}", path)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"config field {path!r}: expected a str, got {value!r}", path)
        return value
    raise ConfigError(f"config field {path!r}: unsupported annotation {tp!r}", path)


def from_plain(cls: type, data: Any, prefix: str) -> Any:
    where = prefix or cls.__name__
    if not isinstance(data, dict):
        raise ConfigError(f"config field {where!r}: expected a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = dataclasses.fields(cls)
    names = [f.name for f in fields]
    unknown = sorted(set(data) - set(names))
    if unknown:
        path = f"{prefix}.{unknown[0]}" if prefix else unknown[0]
        raise ConfigError(
            f"config field {path!r} is unknown to this code ({cls.__name__} has {names})"
        )
    data = {**{f.name: f.metadata[ABSENT] for f in fields if ABSENT in f.metadata}, **data}
    missing = [n for n in names if n not in data]
    if missing:
        path = f"{prefix}.{missing[0]}" if prefix else missing[0]
        raise ConfigError(f"config field {path!r} is missing", path)
    kwargs = {}
    for name in names:
        path = f"{prefix}.{name}" if prefix else name
        kwargs[name] = _convert(hints[name], data[name], path)
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if exc.field is None:
            raise ConfigError(f"config section {where!r}: {exc}") from exc
        path = f"{prefix}.{exc.field}" if prefix else exc.field
        raise ConfigError(f"config field {path!r}: {exc}", path) from exc
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"config section {where!r}: {exc}") from exc


ALIASES: dict[str, str] = {
    "fusion": "fusion.kind",
    "agent_size": "fusion.agent_size",
    "text_fusion": "text_fusion.kind",
    "graph_k": "text_fusion.graph_k",
    "anchor": "head.anchor",
    "text_encoder": "text.encoder",
    "classes": "head.classes",
}
"""Short override names accepted by :func:`apply_overrides` (and ``build_model``)."""


def apply_overrides(cfg: T, **overrides: Any) -> T:
    """A copy of ``cfg`` with overrides applied.

    Keys are a top-level field (``modalities="lidar"``), a short alias from :data:`ALIASES`
    (``fusion="bi_mhca"``, ``anchor="center"``, ``text_encoder="gru"``, ``agent_size=(8, 8)``,
    ``graph_k=(4, 4, 2)``, ``text_fusion="ggf"``) or a section and field joined by a double
    underscore (``head__score_threshold=0.3``, ``fusion__heads=2``). Values are validated by the
    dataclasses; whole sections (e.g. ``head=HeadConfig(...)``) may be passed too.
    """
    cls = type(cfg)
    data = to_plain(cfg)
    sections = {f.name for f in dataclasses.fields(cls)}
    for key, value in overrides.items():
        path = ALIASES.get(key, key.replace("__", "."))
        parts = path.split(".")
        if parts[0] not in sections:
            raise ConfigError(
                f"unknown override {key!r}; use a field of ModelConfig {sorted(sections)}, "
                f"an alias {sorted(ALIASES)} or 'section__field'"
            )
        node = data
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                raise ConfigError(f"unknown override {key!r}: {part!r} is not a config section")
            node = node[part]
        if parts[-1] not in node:
            raise ConfigError(f"unknown override {key!r}: no field {path!r}")
        node[parts[-1]] = to_plain(value)
    return from_plain(cls, data, "")
