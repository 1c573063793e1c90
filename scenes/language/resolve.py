"""The exact meaning of a language-suite query (:mod:`scenes.language.query`) over a frame's actors.

Independent of :mod:`scenes.language.prompts` by design (the suite checks language the generator did not
write). Conventions: LiDAR frame, x forward, y left, metres; BEV box centres; ground velocities
(:class:`scenes.geometry.actors.Actor`). Like a careful annotator, :func:`resolve` **refuses** a sentence in
a scene where its answer is borderline, rather than guess; a refused (sentence, scene) pair is
not a case of the suite.

**Where actors count.** An actor is *referable* when its centre has ``0 <= x <= 50`` m and
``|atan2(y, x)| <= 32`` degrees (View-of-Delft's annotated area, the camera's view). It is
*clearly inside* with 1 m / 1 degree to spare, and in the *edge band* when it is not clearly inside
but within ``-5 <= x <= 55`` m and 37 degrees (visible, yet maybe not annotated). Others are
ignored. The caller passes only the actors a person could see (e.g. leaves out unsensed ones).

**Margins.** Each condition gives an actor a signed margin in units of its slack (> 0: holds).
``|margin| < 1`` is *borderline*: a sentence is refused when any actor of its class in the area
is borderline, or an edge-band actor would match with one unit of slack (margin > -1). A
conjunction takes the least margin, a negation the opposite. The conditions:

* ``moving``: ground speed > 0.5 m/s (:data:`scenes.geometry.actors.MOVING_SPEED`); slack 0.2 m/s.
* ``side``: left = centre ``y > 1.5`` m, right = ``y < -1.5`` m (slack 0.3 m); ahead =
  ``|y| <= 1.5`` m and ``|bearing| <= 15`` degrees (slack 0.3 m, 1 degree).
* ``heading``: ground radial velocity ``v_r`` (along the line of sight to the centre, + = away):
  approaching = ``v_r < -0.5``, away = ``v_r > 0.5`` m/s (slack 0.2); crossing = moving and the
  velocity within 30 degrees of the y axis (slack 5 degrees).
* ``speed_above V`` = speed > V; ``speed_below V`` = moving and speed < V; ``speed_about V`` =
  ``|speed - V| <= max(0.75, 0.15 V)`` m/s; slack 0.3 m/s.
* depth = the forward distance of the box's nearest point (``x`` less the box's half extent along
  x): ``depth_about D`` = within ``D +- 2.5`` m, ``depth_beyond D`` = ``> D``, ``depth_within D`` =
  ``<= D``, ``depth_between [A, B]``; slack 0.75 m. ("20 m in front of us" is depth about 20.)
* relations to one reference actor ``r`` (its query must pick exactly one actor, else the sentence
  is refused as ambiguous; an actor is never related to itself), BEV centres, slack 0.75 m:
  ``near`` = centre distance <= 5 m; ``behind`` = further from us than ``r`` along our line of
  sight to it (range at least 2 m more, at most 2.5 m off that line); ``in_front_of`` = the same,
  nearer; ``left_of`` / ``right_of`` = ``y`` at least 1.5 m more / less than ``r``'s and ``x``
  within 5 m; ``between`` ``a`` and ``b`` = projected on the segment at least 1 m from either end
  and at most 2.5 m off it.

**Ranks** order the actors a query matches and pick the ``index``-th: ``nearest`` / ``farthest``
by centre range ``hypot(x, y)`` (and the nearest-point depth must rank the same actor there, so
"closest" means the same either way), ``leftmost`` / ``rightmost`` by ``y`` (and the bearing
must rank the same actor: left in the lane and left in the view agree), ``fastest`` /
``slowest`` by speed among the moving (a borderline mover refuses; so does a standing actor for
``slowest``, which it might be said to be), ``nearest_to`` by centre distance to a reference
actor. Refused when fewer actors than ``index`` match or the picked value lies within the rank
gap of its neighbours: 1.5 m of range or distance, 1.0 m of ``y``, 1.0 m/s.

**Exclusion** removes the actors matching ``except.where`` (with the same borderline rule) or the
one at ``except.rank`` from the set; refused when nothing is left or nothing is removed ("all
... except" presumes both). ``one`` ("the X") refuses unless exactly one actor is referred to. ``out_of_class`` queries
(a bus, a dog, nonsense) refer to nothing, in every scene.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from scenes.geometry.actors import MOVING_SPEED, Actor
from scenes.language.query import (
    Cond,
    Depth,
    Exclusion,
    HeadingIs,
    Moving,
    Not,
    OnSide,
    Query,
    Rank,
    Relation,
    Speed,
)

X_RANGE = (0.0, 50.0)
HALF_FOV_DEG = 32.0
REGION_SLACK_M = 1.0
REGION_SLACK_DEG = 1.0
EDGE_BAND_M = 5.0
EDGE_BAND_DEG = 5.0

SLACK_MOTION = 0.2
SLACK_Y = 0.3
SLACK_BEARING = 1.0
SLACK_SPEED = 0.3
SLACK_ANGLE = 5.0
SLACK_DEPTH = 0.75
SLACK_RELATION = 0.75

LANE_HALF_WIDTH = 1.5
AHEAD_BEARING_DEG = 15.0
HEADING_SPEED = 0.5
CROSSING_DEG = 30.0
ABOUT_DEPTH = 2.5
SPEED_ABOUT = (0.75, 0.15)
NEAR_M = 5.0
BEHIND_MIN_M = 2.0
LINE_OFFSET_M = 2.5
BESIDE_MIN_DY = 1.5
BESIDE_MAX_DX = 5.0
BETWEEN_END_M = 1.0
RANK_GAP = {"range": 1.5, "y": 1.0, "speed": 1.0}


class RefusalError(Exception):
    """The answer is borderline or the sentence's presupposition fails in this scene."""


@dataclass(frozen=True)
class Resolution:
    """A query's answer in one scene: referent ``ids`` (ascending), or why it was ``refused``."""

    ids: tuple[int, ...] = ()
    refused: str | None = None


def region_state(actor: Actor) -> str:
    """``inside`` (clearly), ``edge`` (the band around the area's border) or ``outside``."""
    x, y = float(actor.box[0]), float(actor.box[1])
    bearing = abs(math.degrees(math.atan2(y, x)))
    lo, hi = X_RANGE
    if (
        lo + REGION_SLACK_M <= x <= hi - REGION_SLACK_M
        and bearing <= HALF_FOV_DEG - REGION_SLACK_DEG
    ):
        return "inside"
    if lo - EDGE_BAND_M <= x <= hi + EDGE_BAND_M and bearing <= HALF_FOV_DEG + EDGE_BAND_DEG:
        return "edge"
    return "outside"


def referable(actor: Actor) -> bool:
    """Inside the annotated area (no slack): ``0 <= x <= 50`` and ``|bearing| <= 32`` degrees."""
    x, y = float(actor.box[0]), float(actor.box[1])
    return X_RANGE[0] <= x <= X_RANGE[1] and abs(math.degrees(math.atan2(y, x))) <= HALF_FOV_DEG


def depth(actor: Actor) -> float:
    """Forward distance (m) of the box's nearest point: centre x less the half extent along x."""
    x, _, _, length, width, _, yaw = (float(v) for v in actor.box)
    return x - abs(0.5 * length * math.cos(yaw)) - abs(0.5 * width * math.sin(yaw))


def centre_range(actor: Actor) -> float:
    """BEV distance (m) of the box centre from the sensor."""
    return float(math.hypot(actor.box[0], actor.box[1]))


def _moving(a: Actor) -> float:
    return (a.speed - MOVING_SPEED) / SLACK_MOTION


def _side(a: Actor, side: str) -> float:
    y = float(a.box[1])
    if side == "left":
        return (y - LANE_HALF_WIDTH) / SLACK_Y
    if side == "right":
        return (-y - LANE_HALF_WIDTH) / SLACK_Y
    bearing = abs(math.degrees(math.atan2(y, float(a.box[0]))))
    return min((LANE_HALF_WIDTH - abs(y)) / SLACK_Y, (AHEAD_BEARING_DEG - bearing) / SLACK_BEARING)


def _heading(a: Actor, heading: str) -> float:
    vr = a.radial_velocity
    if heading == "approaching":
        return (-vr - HEADING_SPEED) / SLACK_MOTION
    if heading == "away":
        return (vr - HEADING_SPEED) / SLACK_MOTION
    vx, vy = (abs(float(v)) for v in a.velocity)
    angle = math.degrees(math.atan2(vx, vy)) if a.speed > 1e-9 else 90.0
    return min(_moving(a), (CROSSING_DEG - angle) / SLACK_ANGLE)


def _speed(a: Actor, c: Speed) -> float:
    if c.op == "speed_above":
        return (a.speed - c.mps) / SLACK_SPEED
    if c.op == "speed_below":
        return min(_moving(a), (c.mps - a.speed) / SLACK_SPEED)
    tol = max(SPEED_ABOUT[0], SPEED_ABOUT[1] * c.mps)
    return (tol - abs(a.speed - c.mps)) / SLACK_SPEED


def _depth(a: Actor, c: Depth) -> float:
    d = depth(a)
    if c.op == "depth_about":
        return (ABOUT_DEPTH - abs(d - c.lo)) / SLACK_DEPTH
    if c.op == "depth_beyond":
        return (d - c.lo) / SLACK_DEPTH
    if c.op == "depth_within":
        return (c.lo - d) / SLACK_DEPTH
    assert c.hi is not None
    return min(d - c.lo, c.hi - d) / SLACK_DEPTH


def _relation(a: Actor, kind: str, refs: Sequence[Actor]) -> float:
    if any(a.actor_id == r.actor_id for r in refs):
        return -math.inf
    s = a.box[:2].astype(float)
    if kind == "between":
        p, q = (r.box[:2].astype(float) for r in refs)
        length = float(math.hypot(*(q - p)))
        if length < 1e-6:
            return -math.inf
        u = (q - p) / length
        t = float(u @ (s - p))
        off = abs(float(u[0] * (s - p)[1] - u[1] * (s - p)[0]))
        along = min(t - BETWEEN_END_M, length - t - BETWEEN_END_M)
        return min(along, LINE_OFFSET_M - off) / SLACK_RELATION
    r = refs[0].box[:2].astype(float)
    if kind == "near":
        return (NEAR_M - float(math.hypot(*(s - r)))) / SLACK_RELATION
    if kind in ("behind", "in_front_of"):
        ray = r / max(float(math.hypot(*r)), 1e-6)
        off = abs(float(ray[0] * s[1] - ray[1] * s[0]))
        further = float(math.hypot(*s)) - float(math.hypot(*r))
        ahead = further if kind == "behind" else -further
        return min(ahead - BEHIND_MIN_M, LINE_OFFSET_M - off) / SLACK_RELATION
    dy = s[1] - r[1] if kind == "left_of" else r[1] - s[1]
    return min(dy - BESIDE_MIN_DY, BESIDE_MAX_DX - abs(s[0] - r[0])) / SLACK_RELATION


class _Scene:
    """One scene's actors and the reference objects resolved so far."""

    def __init__(self, actors: Sequence[Actor]) -> None:
        self.actors = [a for a in actors if region_state(a) != "outside"]
        self.by_id = {a.actor_id: a for a in self.actors}

    def margin(self, a: Actor, cond: Cond) -> float:
        if isinstance(cond, Moving):
            return _moving(a)
        if isinstance(cond, OnSide):
            return _side(a, cond.side)
        if isinstance(cond, HeadingIs):
            return _heading(a, cond.heading)
        if isinstance(cond, Speed):
            return _speed(a, cond)
        if isinstance(cond, Depth):
            return _depth(a, cond)
        if isinstance(cond, Not):
            return -self.margin(a, cond.cond)
        if isinstance(cond, Relation):
            return _relation(a, cond.kind, [self.reference(q) for q in cond.refs])
        raise TypeError(f"unknown condition {cond!r}")

    def reference(self, query: Query) -> Actor:
        ids = self.select(query)
        if len(ids) != 1:
            raise RefusalError(f"the reference object picks {len(ids)} actors, not one")
        return self.by_id[ids[0]]

    def matching(
        self, pool: Sequence[Actor], where: Sequence[Cond]
    ) -> tuple[list[Actor], list[Actor]]:
        """The actors of ``pool`` clearly inside that clearly match ``where``, and the edge-band
        actors that would match with one unit of slack; RefusalError on a borderline actor."""
        clear, edge = [], []
        for a in pool:
            m = min((self.margin(a, c) for c in where), default=math.inf)
            inside = region_state(a) == "inside"
            if inside and abs(m) < 1.0:
                raise RefusalError(f"actor {a.actor_id} is borderline (margin {m:.2f})")
            if inside and m >= 1.0:
                clear.append(a)
            elif not inside and m > -1.0:
                edge.append(a)
        return clear, edge

    def ranked(self, cands: Sequence[Actor], rank: Rank, edge: Sequence[Actor] = ()) -> Actor:
        """The actor at ``rank`` among ``cands``; ``edge`` actors take part in the order and refuse
        the sentence when they rank at or before it."""
        key, kind = _rank_key(rank, self)
        edge_ids = {a.actor_id for a in edge}
        cands = [*cands, *edge]
        if rank.key in ("fastest", "slowest"):
            for a in cands:
                if abs(_moving(a)) < 1.0:
                    raise RefusalError(f"actor {a.actor_id} is a borderline mover")
                if rank.key == "slowest" and not a.is_moving:
                    raise RefusalError(f"actor {a.actor_id} stands still: is it the slowest?")
            cands = [a for a in cands if a.is_moving]
        if rank.key == "nearest_to" and rank.ref is not None:
            ref = self.reference(rank.ref)
            cands = [a for a in cands if a.actor_id != ref.actor_id]
        if len(cands) < rank.index:
            raise RefusalError(f"{len(cands)} actors to rank, fewer than {rank.index}")
        order = sorted(cands, key=key)
        k = rank.index - 1
        values = [key(a) for a in order]
        for j in (k - 1, k + 1):
            if 0 <= j < len(values) and abs(values[j] - values[k]) < RANK_GAP[kind]:
                raise RefusalError(
                    f"rank {rank.index} by {rank.key} is within {RANK_GAP[kind]} of the next"
                )
        if rank.key in _SECOND_KEYS:
            other = sorted(cands, key=_SECOND_KEYS[rank.key])
            if other[k].actor_id != order[k].actor_id:
                raise RefusalError(f"the two readings of {rank.key} rank different actors")
        if any(a.actor_id in edge_ids for a in order[: k + 1]):
            raise RefusalError("an actor at the edge of the annotated area ranks at or before it")
        return order[k]

    def select(self, query: Query) -> tuple[int, ...]:
        if query.out_of_class is not None:
            return ()
        pool = [a for a in self.actors if query.cls is None or a.cls == query.cls]
        picked, edge = self.matching(pool, query.where)
        if query.rank is not None:
            picked = [self.ranked(picked, query.rank, edge)]
        elif edge:
            raise RefusalError(
                f"actor {edge[0].actor_id} at the edge of the annotated area would match"
            )
        if query.exclusion is not None:
            removed = self._excluded(picked, query.exclusion)
            picked = [a for a in picked if a.actor_id not in removed]
            if not picked or not removed:
                raise RefusalError(f"the exclusion leaves {len(picked)} and removes {len(removed)}")
        if query.one and len(picked) != 1:
            raise RefusalError(f"'the' one actor, but {len(picked)} match")
        return tuple(sorted(a.actor_id for a in picked))

    def _excluded(self, picked: Sequence[Actor], exclusion: Exclusion) -> set[int]:
        if exclusion.rank is not None:
            return {self.ranked(picked, exclusion.rank).actor_id}
        return {a.actor_id for a in self.matching(picked, exclusion.where)[0]}


_SECOND_KEYS: dict[str, Callable[[Actor], float]] = {
    "nearest": depth,
    "farthest": lambda a: -depth(a),
    "leftmost": lambda a: -math.atan2(float(a.box[1]), float(a.box[0])),
    "rightmost": lambda a: math.atan2(float(a.box[1]), float(a.box[0])),
}
"""The other reading of a rank (nearest-point depth for range, bearing for y); both must agree."""


def _rank_key(rank: Rank, scene: _Scene) -> tuple[Callable[[Actor], float], str]:
    """The sort key (ascending = first) of a rank and its gap kind."""
    if rank.key == "nearest":
        return centre_range, "range"
    if rank.key == "farthest":
        return (lambda a: -centre_range(a)), "range"
    if rank.key == "leftmost":
        return (lambda a: -float(a.box[1])), "y"
    if rank.key == "rightmost":
        return (lambda a: float(a.box[1])), "y"
    if rank.key == "fastest":
        return (lambda a: -a.speed), "speed"
    if rank.key == "slowest":
        return (lambda a: a.speed), "speed"
    assert rank.ref is not None
    ref = scene.reference(rank.ref)
    centre = ref.box[:2]
    return (lambda a: float(math.hypot(*(a.box[:2] - centre)))), "range"


def resolve(query: Query, actors: Sequence[Actor]) -> Resolution:
    """The referents of ``query`` among ``actors`` (LiDAR frame), or the reason it is refused.

    Args:
        query: A parsed query (:func:`scenes.language.query.parse_query`).
        actors: The frame's actors a person could see (unique ids).

    Returns:
        :class:`Resolution`: ascending referent ids (possibly none), or ``refused`` set.
    """
    ids = [a.actor_id for a in actors]
    if len(set(ids)) != len(ids):
        raise ValueError("resolve: duplicate actor ids")
    try:
        return Resolution(ids=_Scene(actors).select(query))
    except RefusalError as exc:
        return Resolution(refused=str(exc))
