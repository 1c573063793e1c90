"""Tests for scenes.language.prompts: exact referents, rendering, tags, flip, describe().

The phrasing variants and their train / held-out split: tests/scenes/language/test_prompt_phrasing.py.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from scenes.language.prompts import (
    DEFAULT_REGION,
    ActorFeatures,
    DepthAbout,
    DepthBetween,
    DepthBeyond,
    DepthWithin,
    Extreme,
    Heading,
    HeadingIs,
    MotionState,
    OnSide,
    Predicate,
    Prompt,
    ReferableRegion,
    Side,
    SpeedAbout,
    SpeedAbove,
    SpeedBelow,
    SpeedUnit,
    analyse,
    describe,
    flip_left_right,
    generate_prompts,
    infer_tags,
    render,
    resolve,
)
from tests.scenes.language.prompt_helpers import (
    CAR,
    SINGULAR_NOUNS,
    flip_world,
    hand_world,
    has_phrase,
    is_plural,
    make_actor,
    random_world,
    read_numbers,
)

# ---------------------------------------------------------------------------------------------
# Semantics on the hand-built world
# ---------------------------------------------------------------------------------------------


def test_features_hand_computed():
    f = {a.actor_id: ActorFeatures.of(a) for a in hand_world()}
    assert f[0].depth == pytest.approx(17.75)
    assert f[1].depth == pytest.approx(27.75)
    assert f[3].depth == pytest.approx(7.7)
    assert f[0].radial_velocity == pytest.approx(10 * 20 / math.hypot(20, 3.5))
    assert f[1].radial_velocity == pytest.approx(-8 * 30 / math.hypot(30, 3.5))
    assert f[3].radial_velocity == pytest.approx(-1.4 * 2.5 / math.hypot(8, 2.5))
    assert f[3].crossing_angle_deg == pytest.approx(0.0)
    assert f[2].bearing_deg == pytest.approx(math.degrees(math.atan2(-5, 12)))


@pytest.mark.parametrize(
    ("pred", "expected"),
    [
        (Predicate("Car"), (0, 1, 2)),
        (Predicate("Car", (MotionState(False),)), (2,)),
        (Predicate("Car", (HeadingIs(Heading.AWAY),)), (0,)),  # 6 and 7 are not referable
        (Predicate(None, (HeadingIs(Heading.AWAY),)), (0, 5)),  # nor is 8
        (Predicate("Pedestrian"), (3, 4)),
        (Predicate("Pedestrian", (HeadingIs(Heading.CROSSING),)), (3,)),
        (Predicate("Pedestrian", (MotionState(True),)), (3,)),
        (Predicate("Pedestrian", (HeadingIs(Heading.APPROACHING),)), ()),  # v_r -0.42 > -0.5
        (Predicate(None, (OnSide(Side.LEFT),)), (0, 3)),
        (Predicate(None, (OnSide(Side.RIGHT),)), (1, 2)),
        (Predicate(None, (OnSide(Side.AHEAD),)), (4, 5)),
        (Predicate(None, (DepthAbout(10.0),)), (2, 3)),
        # nearest edge, not centre: car 0 (centre x 20) is within 18 m, the cyclist (centre x 25)
        # is not further than 24.5 m.
        (Predicate(None, (DepthWithin(18.0),)), (0, 2, 3, 4)),
        (Predicate(None, (DepthBeyond(24.5),)), (1,)),
        (Predicate(None, (DepthBetween(10.0, 20.0),)), (0, 4)),
        (Predicate(None, (SpeedAbove(30.0, SpeedUnit.KMH),)), (0,)),
        (Predicate(None, (SpeedAbout(30.0, SpeedUnit.KMH),)), (1,)),  # |8 - 8.33| <= 1.25
        (Predicate(None, (SpeedBelow(2.0, SpeedUnit.MPS),)), (3,)),  # moving and < 2 m/s
        (Predicate("Car", (OnSide(Side.RIGHT), HeadingIs(Heading.APPROACHING))), (1,)),
        (Predicate("Cyclist", (HeadingIs(Heading.AWAY), DepthAbout(25.0))), (5,)),
        (Predicate("Car", (), Extreme.NEAREST), (2,)),
        (Predicate(None, (), Extreme.LEFTMOST), (0,)),
        (Predicate("Car", (), Extreme.FASTEST), (0,)),
        (Predicate("Pedestrian", (), Extreme.FASTEST), (3,)),
        (Predicate("Pedestrian", (MotionState(False),), Extreme.FASTEST), ()),
    ],
)
def test_resolve_hand_world(pred, expected):
    assert resolve(pred, hand_world()) == expected


def test_region_is_a_parameter():
    world = hand_world()
    near = ReferableRegion(x_max=20.0)
    assert resolve(Predicate("Car"), world, near) == (0, 2)  # centre x 20 is inside, 30 not
    narrow = ReferableRegion(half_fov_deg=10.0)
    assert resolve(Predicate("Car"), world, narrow) == (0, 1)  # car 2 is at -22.6 deg


def test_guard_band_conflict_makes_prompt_unusable():
    world = [*hand_world(), make_actor(9, "Car", 52.0, 0.0, 0.0, (8.0, 0.0), CAR)]
    res = analyse(Predicate("Car", (HeadingIs(Heading.AWAY),)), world)
    assert res.ids == (0,)
    assert res.conflicts == (9,)
    assert not res.usable
    assert analyse(Predicate("Car", (MotionState(False),)), world).usable
    for seed in range(5):
        for p in generate_prompts(world, np.random.default_rng(seed), 12):
            assert not p.predicate.matches(world[-1], 1.0), p.text


def test_crispness():
    world = hand_world()
    # pedestrian 3 has v_r -0.42: within the 0.2 m/s slack of the approaching threshold
    assert not analyse(Predicate("Pedestrian", (HeadingIs(Heading.APPROACHING),)), world).crisp
    assert analyse(Predicate("Car", (HeadingIs(Heading.AWAY),)), world).crisp
    # car 0's nearest edge is 17.75 m: 0.25 m from the edge of "about 20 m"
    assert not analyse(Predicate("Car", (DepthAbout(20.0),)), world).crisp


def test_duplicate_ids_and_bad_predicates_raise():
    world = hand_world()
    with pytest.raises(ValueError, match="duplicate actor_id"):
        resolve(Predicate("Car"), [*world, world[0]])
    with pytest.raises(ValueError, match="one atom per family"):
        Predicate("Car", (DepthAbout(10.0), DepthWithin(20.0)))
    with pytest.raises(ValueError, match="class"):
        Predicate("Tram")  # a Truck is a class of the nuscenes set
    assert Predicate("Car", (DepthAbout(10.0), OnSide(Side.LEFT))) == Predicate(
        "Car", (OnSide(Side.LEFT), DepthAbout(10.0))
    )


# ---------------------------------------------------------------------------------------------
# Rendering
# ---------------------------------------------------------------------------------------------


def _agrees(text: str, n: int) -> None:
    """Singular / plural noun, is / are and any stated count agree with ``n`` referents."""
    assert is_plural(text) == (n > 1), (n, text)
    if n == 1:
        assert any(has_phrase(text, w) for w in SINGULAR_NOUNS), text
    assert not has_phrase(text, "is" if n > 1 else "are"), (n, text)
    _, counts = read_numbers(text)
    assert all(c == n for c in counts), (n, counts, text)


def test_render_singular_plural_and_counts():
    pred = Predicate("Car", (HeadingIs(Heading.AWAY),))
    cars = re.compile(r"\b(?:cars|vehicles|automobiles|autos|motor vehicles)\b", re.IGNORECASE)
    for seed in range(30):
        plain = render(pred, 1, np.random.default_rng(seed), p_frame=0.0, p_restyle=0.0)
        assert plain[0].isupper() and plain.endswith("."), plain  # Talk2Radar style
        assert plain.split()[0] == "The", plain
        one = render(pred, 1, np.random.default_rng(seed))
        _agrees(one, 1)
        three = render(pred, 3, np.random.default_rng(seed), p_count_word=1.0)
        _agrees(three, 3)
        assert read_numbers(three)[1] == [3.0], three
        assert cars.search(three), three
        two = render(pred, 2, np.random.default_rng(seed), p_count_word=1.0)
        _agrees(two, 2)
        assert read_numbers(two)[1] == [2.0], two
        many = render(pred, 12, np.random.default_rng(seed), p_count_word=1.0)
        _agrees(many, 12)
        assert read_numbers(many)[1] == [], many  # counts are stated up to ten
    with pytest.raises(ValueError):
        render(pred, 0, np.random.default_rng(0))
    with pytest.raises(ValueError):
        render(Predicate("Car", (), Extreme.NEAREST), 2, np.random.default_rng(0))
    with pytest.raises(ValueError, match="phrasing"):
        render(pred, 1, np.random.default_rng(0), phrasing="test")


def test_render_units_vary():
    pred = Predicate("Pedestrian", (DepthAbout(10.0),))
    texts = {render(pred, 2, np.random.default_rng(s)) for s in range(80)}
    for unit in ("m", "meters", "metres"):
        assert any(re.search(rf"\b10 {unit}\b", t, re.IGNORECASE) for t in texts), unit
    assert any(re.search(r"\bten (?:meters|metres)\b", t, re.IGNORECASE) for t in texts)
    speed = Predicate("Car", (SpeedAbout(30.0, SpeedUnit.KMH),))
    texts = {render(speed, 1, np.random.default_rng(s)) for s in range(80)}
    for unit in ("30 km/h", "30 kph", "30 kilometres per hour", "thirty kilometres per hour"):
        assert any(unit in t.lower() for t in texts), unit


# ---------------------------------------------------------------------------------------------
# Generation over many worlds
# ---------------------------------------------------------------------------------------------


def _generated(n_worlds=80, per_world=6, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_worlds):
        world = random_world(rng, int(rng.integers(2, 16)))
        out.append((world, generate_prompts(world, rng, per_world)))
    return out


@pytest.fixture(scope="module")
def generated():
    return _generated()


def test_generated_prompts_are_exact_and_well_formed(generated):
    total = 0
    n_plural = 0
    for world, prompts in generated:
        texts = [p.text.lower().rstrip(".!?") for p in prompts]
        assert len(set(texts)) == len(texts)
        assert len({p.predicate for p in prompts}) == len(prompts)
        by_id = {a.actor_id: a for a in world}
        for p in prompts:
            total += 1
            res = analyse(p.predicate, world)
            assert p.referent_ids, p.text
            assert p.referent_ids == res.ids == resolve(p.predicate, world)
            assert res.crisp and not res.conflicts
            assert all(DEFAULT_REGION.contains(by_id[i]) for i in p.referent_ids)
            n = len(p.referent_ids)
            n_plural += n > 1
            _agrees(p.text, n)
            assert len(p.text.split()) <= 22
    assert total > 200
    assert n_plural > 0.15 * total


def test_generated_tags_match_keywords(generated):
    seen = set()
    for _, prompts in generated:
        for p in prompts:
            assert p.tags == p.predicate.tags == infer_tags(p.text), p.text
            seen |= p.tags
    assert seen == {"class", "depth", "velocity", "motion", "position"}


def test_no_prompt_for_empty_or_out_of_range_world():
    rng = np.random.default_rng(0)
    assert generate_prompts([], rng, 5) == []
    behind = [make_actor(0, "Car", -10.0, 0.0, 0.0, (3.0, 0.0), CAR)]
    assert generate_prompts(behind, rng, 5) == []
    assert generate_prompts(hand_world(), rng, 0) == []


def test_generation_is_deterministic():
    world = random_world(np.random.default_rng(3), 12)
    a = generate_prompts(world, np.random.default_rng(11), 8)
    b = generate_prompts(world, np.random.default_rng(11), 8)
    c = generate_prompts(world, np.random.default_rng(12), 8)
    assert a == b
    assert [p.text for p in a] != [p.text for p in c]


# ---------------------------------------------------------------------------------------------
# Keyword tags on real-style prompts
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "tags"),
    [
        (
            "The pedestrians walking towards the ego car about 10 meters ahead on the left.",
            {"class", "motion", "depth", "position"},
        ),
        ("The car at a speed of 30 km/h.", {"class", "velocity"}),
        ("the car 20 meters away from us", {"class", "depth"}),
        ("The vehicle moving away from us", {"class", "motion"}),
        ("The cyclist in front of the ego vehicle.", {"class", "position"}),
        ("the car directly ahead", {"class", "position"}),
        ("the car 15m ahead", {"class", "depth"}),
        ("the cyclist riding at 3 m/s", {"class", "velocity"}),
        ("The parked cars on the right side of the road.", {"class", "motion", "position"}),
        ("The nearest object approaching the ego vehicle", {"depth", "motion"}),
        ("a fast car behind the truck", {"class", "velocity", "position"}),
    ],
)
def test_infer_tags_real_style(text, tags):
    assert infer_tags(text) == frozenset(tags)


def test_prompt_from_text():
    p = Prompt.from_text("The car on the left.", [3, 1])
    assert p.referent_ids == (1, 3)
    assert p.tags == frozenset({"class", "position"})
    assert p.predicate is None


# ---------------------------------------------------------------------------------------------
# Left-right flip
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "flipped"),
    [
        ("The car on the left.", "The car on the right."),
        ("Left lane, RIGHT side", "Right lane, LEFT side"),
        ("the leftmost cyclist on our right", "the rightmost cyclist on our left"),
        ("on the left-hand side", "on the right-hand side"),
        ("crossing from left to right", "crossing from right to left"),
        ("the car right in front of us on the left", "the car right in front of us on the right"),
        ("on the right in front of the bus", "on the left in front of the bus"),
        ("bright copyright leftover", "bright copyright leftover"),
    ],
)
def test_flip_left_right_text(text, flipped):
    assert flip_left_right(text) == flipped


def test_flip_world_keeps_referents_and_text(generated):
    checked = 0
    for world, prompts in generated[:40]:
        mirrored = flip_world(world)
        for k, p in enumerate(prompts):
            fp = p.flipped()
            assert resolve(fp.predicate, mirrored) == p.referent_ids, p.text
            assert infer_tags(fp.text) == p.tags
            assert flip_left_right(fp.text) == p.text
            n = len(p.referent_ids)
            a = render(p.predicate, n, np.random.default_rng(k))
            b = render(p.predicate.flipped(), n, np.random.default_rng(k))
            assert b == flip_left_right(a)
            checked += 1
    assert checked > 100
    assert Predicate("Car", (OnSide(Side.LEFT),), Extreme.LEFTMOST).flipped() == Predicate(
        "Car", (OnSide(Side.RIGHT),), Extreme.RIGHTMOST
    )


# ---------------------------------------------------------------------------------------------
# describe(): the annotation tool's suggester
# ---------------------------------------------------------------------------------------------


def test_describe_hand_world():
    world = hand_world()
    rng = np.random.default_rng(0)
    cars = describe([world[0], world[1], world[2]], world, rng)
    assert cars.predicate == Predicate("Car")
    assert cars.referent_ids == (0, 1, 2)
    away = describe([world[5], world[0]], world, rng)
    assert away.predicate == Predicate(None, (HeadingIs(Heading.AWAY),))
    assert away.referent_ids == (0, 5)
    assert away.tags == infer_tags(away.text) == frozenset({"motion"})
    assert describe([], world, rng) is None
    assert describe([world[6]], world, rng) is None  # beyond 50 m: not referable
    for a in world[:6]:
        d = describe([a], world, rng)
        assert d is not None and resolve(d.predicate, world) == (a.actor_id,), a.actor_id


def test_describe_round_trip_random_worlds(generated):
    rng = np.random.default_rng(5)
    singles = found_singles = sets = found_sets = 0
    for world, prompts in generated[:50]:
        referable = [a for a in world if DEFAULT_REGION.contains(a)]
        subsets = [[a] for a in referable]
        subsets += [[a for a in world if a.actor_id in p.referent_ids] for p in prompts]
        if len(referable) >= 2:
            pick = rng.choice(len(referable), size=2, replace=False)
            subsets.append([referable[int(i)] for i in pick])
        for sub in subsets:
            d = describe(sub, world, rng)
            want = tuple(sorted(a.actor_id for a in sub))
            if len(sub) == 1:
                singles += 1
                found_singles += d is not None
            else:
                sets += 1
                found_sets += d is not None
            if d is None:
                continue
            res = analyse(d.predicate, world)
            assert d.referent_ids == res.ids == want, d.text
            assert not res.conflicts
            assert d.tags == infer_tags(d.text), d.text
            _agrees(d.text, len(want))
            assert d.text[0].isupper() and d.text.endswith("."), d.text
    assert singles > 100 and found_singles >= 0.9 * singles
    assert found_sets >= 0.5 * sets
