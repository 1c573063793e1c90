"""The hand-written meaning of a sentence of the language suite: a small query over a frame's actors.

The language suite (``bench/data/language_suite.json``, run by ``python -m bench.language_suite``)
pairs sentences written by a person with a query written by the same person; this module is the
query's form and its strict JSON reader, :mod:`scenes.language.resolve` its exact meaning. Neither
imports :mod:`scenes.language.prompts`: the suite measures language the generator did not write, so its
referents must not come from the generator's semantics either.

JSON form (every key optional unless said; unknown keys are errors)::

    Query  = {"class": "Car" | "Pedestrian" | "Cyclist" | null,   # null / absent: any class
                                                # (or any class of a preset: "Truck", "Bus", ...)
              "where": [Cond, ...],                                # conjunction
              "rank": Rank,                                        # the one actor at a rank
              "except": {"where": [Cond, ...]} | {"rank": Rank},  # removed from the set
              "one": true,                                        # "the X": exactly one referent
              "out_of_class": "bus"}                              # names no class: always empty
    Cond   = {"op": "moving"} | {"op": "side", "side": "left" | "right" | "ahead"}
           | {"op": "heading", "heading": "approaching" | "away" | "crossing"}
           | {"op": "speed_above" | "speed_below" | "speed_about", "value": V, "unit": "kmh" | "mps"}
           | {"op": "depth_about" | "depth_beyond" | "depth_within", "m": D}
           | {"op": "depth_between", "m": [A, B]}
           | {"op": "not", "cond": Cond}
           | {"op": "near" | "behind" | "in_front_of" | "left_of" | "right_of", "of": Query}
           | {"op": "between", "of": [Query, Query]}
    Rank   = {"by": "nearest" | "farthest" | "leftmost" | "rightmost" | "fastest" | "slowest"
                    | "nearest_to", "index": k (1 = first), "of": Query (only for nearest_to)}

A query with ``out_of_class`` has no other key. A reference object (``of``) is itself a query
that must pick exactly one actor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from scenes.geometry.classes import ALL_CLASSES

SIDES = ("left", "right", "ahead")
HEADINGS = ("approaching", "away", "crossing")
SPEED_OPS = ("speed_above", "speed_below", "speed_about")
DEPTH_OPS = ("depth_about", "depth_beyond", "depth_within", "depth_between")
RELATIONS = ("near", "behind", "in_front_of", "left_of", "right_of", "between")
RANK_KEYS = ("nearest", "farthest", "leftmost", "rightmost", "fastest", "slowest", "nearest_to")
SPEED_UNITS = {"kmh": 1.0 / 3.6, "mps": 1.0}
"""Metres per second per unit of a stated speed."""


class QueryError(ValueError):
    """A malformed query; the message names the entry and the field."""


@dataclass(frozen=True)
class Moving:
    """Ground speed above :data:`scenes.geometry.actors.MOVING_SPEED`."""


@dataclass(frozen=True)
class OnSide:
    """``side``: left, right or directly ahead (see :mod:`scenes.language.resolve`)."""

    side: str


@dataclass(frozen=True)
class HeadingIs:
    """``heading``: approaching, away or crossing."""

    heading: str


@dataclass(frozen=True)
class Speed:
    """``op`` in :data:`SPEED_OPS` against ``mps`` (the stated ``value`` in ``unit``, in m/s)."""

    op: str
    mps: float
    value: float
    unit: str


@dataclass(frozen=True)
class Depth:
    """``op`` in :data:`DEPTH_OPS`; ``lo`` is D (or A), ``hi`` is B for ``depth_between``."""

    op: str
    lo: float
    hi: float | None = None


@dataclass(frozen=True)
class Not:
    """The negation of ``cond``."""

    cond: Cond


@dataclass(frozen=True)
class Relation:
    """``kind`` in :data:`RELATIONS` to the reference objects ``refs`` (two for ``between``)."""

    kind: str
    refs: tuple[Query, ...]


Cond = Moving | OnSide | HeadingIs | Speed | Depth | Not | Relation


@dataclass(frozen=True)
class Rank:
    """The ``index``-th actor (1-based) in the order ``key``; ``ref`` for ``nearest_to``."""

    key: str
    index: int
    ref: Query | None = None


@dataclass(frozen=True)
class Exclusion:
    """The actors removed from a query's set: those matching ``where``, or the one at ``rank``."""

    where: tuple[Cond, ...] = ()
    rank: Rank | None = None


@dataclass(frozen=True)
class Query:
    """A parsed query (module docstring); ``cls`` None = any class."""

    cls: str | None = None
    where: tuple[Cond, ...] = ()
    rank: Rank | None = None
    exclusion: Exclusion | None = None
    one: bool = False
    out_of_class: str | None = None


def _keys(data: object, allowed: set[str], at: str) -> Mapping[str, object]:
    if not isinstance(data, dict):
        raise QueryError(f"{at}: expected a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise QueryError(
            f"{at}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})"
        )
    return data


def _number(value: object, at: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise QueryError(f"{at}: expected a finite number, got {value!r}")
    return float(value)


def _choice(value: object, options: tuple[str, ...], at: str) -> str:
    if value not in options:
        raise QueryError(f"{at}: {value!r} is not one of {', '.join(options)}")
    return str(value)


def parse_cond(data: object, at: str) -> Cond:
    """One condition from its JSON form; errors name ``at`` (e.g. ``entry neg-03: where[0]``)."""
    if not isinstance(data, dict) or "op" not in data:
        raise QueryError(f"{at}: a condition is an object with an 'op'")
    op = data["op"]
    if op == "moving":
        _keys(data, {"op"}, at)
        return Moving()
    if op == "side":
        _keys(data, {"op", "side"}, at)
        return OnSide(_choice(data.get("side"), SIDES, f"{at}.side"))
    if op == "heading":
        _keys(data, {"op", "heading"}, at)
        return HeadingIs(_choice(data.get("heading"), HEADINGS, f"{at}.heading"))
    if op in SPEED_OPS:
        _keys(data, {"op", "value", "unit"}, at)
        unit = _choice(data.get("unit"), tuple(SPEED_UNITS), f"{at}.unit")
        value = _number(data.get("value"), f"{at}.value")
        if value < 0:
            raise QueryError(f"{at}.value: a speed is >= 0, got {value}")
        return Speed(str(op), value * SPEED_UNITS[unit], value, unit)
    if op in DEPTH_OPS:
        _keys(data, {"op", "m"}, at)
        if op == "depth_between":
            pair = data.get("m")
            if not isinstance(pair, list) or len(pair) != 2:
                raise QueryError(f"{at}.m: depth_between takes [A, B]")
            lo, hi = (_number(v, f"{at}.m") for v in pair)
            if not lo < hi:
                raise QueryError(f"{at}.m: need A < B, got {pair}")
            return Depth(str(op), lo, hi)
        return Depth(str(op), _number(data.get("m"), f"{at}.m"))
    if op == "not":
        _keys(data, {"op", "cond"}, at)
        return Not(parse_cond(data.get("cond"), f"{at}.cond"))
    if op in RELATIONS:
        _keys(data, {"op", "of"}, at)
        refs = data.get("of")
        if op == "between":
            if not isinstance(refs, list) or len(refs) != 2:
                raise QueryError(f"{at}.of: between takes two reference queries")
            return Relation(
                "between", tuple(parse_query(r, f"{at}.of[{i}]") for i, r in enumerate(refs))
            )
        return Relation(str(op), (parse_query(refs, f"{at}.of"),))
    raise QueryError(f"{at}: unknown op {op!r}")


def _where(data: object, at: str) -> tuple[Cond, ...]:
    if not isinstance(data, list):
        raise QueryError(f"{at}: 'where' is a list of conditions")
    return tuple(parse_cond(c, f"{at}[{i}]") for i, c in enumerate(data))


def parse_rank(data: object, at: str) -> Rank:
    """A rank from its JSON form (module docstring)."""
    d = _keys(data, {"by", "index", "of"}, at)
    key = _choice(d.get("by"), RANK_KEYS, f"{at}.by")
    index = d.get("index", 1)
    if isinstance(index, bool) or not isinstance(index, int) or index < 1:
        raise QueryError(f"{at}.index: a rank is an integer >= 1, got {index!r}")
    if (key == "nearest_to") != ("of" in d):
        raise QueryError(f"{at}: 'of' is needed by nearest_to and only by it")
    ref = parse_query(d["of"], f"{at}.of") if "of" in d else None
    return Rank(key, index, ref)


def parse_query(data: object, at: str = "query") -> Query:
    """A :class:`Query` from its JSON form (module docstring).

    Raises:
        QueryError: naming ``at`` and the field.
    """
    d = _keys(data, {"class", "where", "rank", "except", "one", "out_of_class"}, at)
    if "out_of_class" in d:
        if set(d) != {"out_of_class"}:
            raise QueryError(f"{at}: out_of_class stands alone")
        noun = d["out_of_class"]
        if not isinstance(noun, str) or not noun.strip():
            raise QueryError(f"{at}.out_of_class: name the thing (a non-empty string)")
        return Query(out_of_class=noun)
    cls = d.get("class")
    if cls is not None:
        cls = _choice(cls, ALL_CLASSES, f"{at}.class")
    where = _where(d.get("where", []), f"{at}.where")
    rank = parse_rank(d["rank"], f"{at}.rank") if "rank" in d else None
    exclusion = None
    if "except" in d:
        e = _keys(d["except"], {"where", "rank"}, f"{at}.except")
        if len(e) != 1:
            raise QueryError(f"{at}.except: give either 'where' or 'rank'")
        exclusion = Exclusion(
            where=_where(e.get("where", []), f"{at}.except.where"),
            rank=parse_rank(e["rank"], f"{at}.except.rank") if "rank" in e else None,
        )
        if rank is not None:
            raise QueryError(f"{at}: 'rank' and 'except' do not combine")
    one = d.get("one", False)
    if not isinstance(one, bool):
        raise QueryError(f"{at}.one: expected true or false")
    return Query(cls=cls, where=where, rank=rank, exclusion=exclusion, one=one)
