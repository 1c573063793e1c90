"""Tests for the extended prompt language (issue 23): the compositional families' exact
semantics on hand-built worlds, their crispness rejections, base prompts unchanged, perturb()
keeping the meaning words, extended generation (every family, exact referents, tags, flips) and
a synthetic root written with --language extended read back."""

from __future__ import annotations

import hashlib
import re
from collections import Counter

import numpy as np
import pytest

from scenes.language.prompts import (
    HELDOUT_VARIANTS,
    DepthBeyond,
    DepthWithin,
    Exclusion,
    Extreme,
    Heading,
    HeadingIs,
    MotionState,
    Not,
    OnSide,
    Ordinal,
    Predicate,
    PromptConfig,
    Related,
    Relation,
    Side,
    SpeedAbove,
    analyse,
    flip_left_right,
    generate_prompts,
    infer_tags,
    is_count_question,
    perturb,
)
from scenes.language.prompts.atoms import BASE_EXTREMES
from scenes.language.prompts.families import Behind, Count, Travel, unsatisfiable
from scenes.language.prompts.features import DEFAULT_REGION, actor_features
from scenes.language.prompts.nouns import OUT_OF_CLASS
from tests.scenes.language.prompt_helpers import (
    CAR,
    CYC,
    PED,
    flip_world,
    hand_world,
    make_actor,
    random_worlds,
)


def _resolve(expr, world):
    return expr.analyse(actor_features(world), DEFAULT_REGION)


# ---------------------------------------------------------------------------------------------
# Exact semantics on the hand world (tests/scenes/language/prompt_helpers.hand_world's table)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("pred", "expected"),
    [
        (Predicate("Car", (Not(MotionState(True)),)), (2,)),
        (Predicate("Car", (Not(OnSide(Side.LEFT)),)), (1, 2)),
        (Predicate("Car", (Not(HeadingIs(Heading.APPROACHING)),)), (0, 2)),
        (Predicate("Car", (Not(DepthBeyond(15.0)),)), (2,)),
        (Predicate("Pedestrian", (Not(MotionState(False)),)), (3,)),
        (Predicate(None, (Not(OnSide(Side.AHEAD)), MotionState(True))), (0, 1, 3)),
        (Predicate("Car", (Not(MotionState(False)),), Extreme.NEAREST), (0,)),
    ],
)
def test_negation_is_the_complement_within_class_and_region(pred, expected):
    res = analyse(pred, hand_world())
    assert res.ids == expected and res.crisp and not res.conflicts


def test_negation_near_a_threshold_is_not_crisp():
    # Car 0's depth is 17.75: "not beyond 17.5 m" is borderline.
    res = analyse(Predicate("Car", (Not(DepthBeyond(17.5)),)), hand_world())
    assert res.ids == (2,) and not res.crisp
    with pytest.raises(ValueError):
        Not(Not(MotionState(True)))


def test_unsatisfiable_needs_every_actor_clear_of_the_threshold():
    feats = actor_features(hand_world())
    approaching_cyclist = Predicate("Cyclist", (HeadingIs(Heading.APPROACHING),))
    assert analyse(approaching_cyclist, hand_world()).ids == ()
    assert unsatisfiable(approaching_cyclist, feats, DEFAULT_REGION)
    assert unsatisfiable(Predicate("Car", (DepthWithin(5.0),)), feats, DEFAULT_REGION)
    # The cyclist's depth is 24.1: "within 24 m" is empty but borderline.
    near_miss = Predicate("Cyclist", (DepthWithin(24.0),))
    assert analyse(near_miss, hand_world()).ids == ()
    assert not unsatisfiable(near_miss, feats, DEFAULT_REGION)
    # A car in the guard band (x = 52) makes "the car beyond 50 m" ambiguous, not empty.
    guard = [*hand_world(), make_actor(9, "Car", 52.0, 0.0, 0.0, (0.0, 0.0), CAR)]
    assert not unsatisfiable(
        Predicate("Car", (DepthBeyond(45.0),)), actor_features(guard), DEFAULT_REGION
    )


def test_behind_us_is_never_true_of_a_referable_actor_and_reads_as_position():
    world = hand_world()
    feats = actor_features(world)
    for cls in ("Car", "Pedestrian", "Cyclist", None):
        pred = Predicate(cls, (Behind(),))
        assert analyse(pred, world).ids == ()
        assert unsatisfiable(pred, feats, DEFAULT_REGION)
    behind = make_actor(9, "Car", -8.0, 0.0, 0.0, (0.0, 0.0), CAR)
    assert Behind().holds(actor_features([behind])[0])
    assert not Behind().holds(feats[0])
    assert infer_tags("the car right behind us") == {"class", "position"}


def test_unsatisfiable_family_writes_every_form():
    """Behind us, contradictions (standing still yet moving) and values beyond any actor appear,
    and each resolves to nothing (checked against the scene, not trusted)."""
    cfg = PromptConfig(language="extended", family_rates=(0, 1, 0, 0, 0, 0, 0))
    rng = np.random.default_rng(11)
    behind = contradiction = absurd = 0
    for world in random_worlds(11, 60):
        feats = actor_features(world)
        for p in generate_prompts(world, rng, 6, config=cfg):
            if p.family != "unsatisfiable":
                continue
            assert p.referent_ids == ()
            assert unsatisfiable(p.predicate, feats, DEFAULT_REGION), p.text
            atoms = p.predicate.atoms
            behind += any(isinstance(a, Behind) for a in atoms)
            contradiction += MotionState(False) in atoms and any(
                isinstance(a, (HeadingIs, Travel, SpeedAbove)) for a in atoms
            )
            absurd += bool(re.search(r"\b([6-9]\d|[1-9]\d\d)\b", p.text))
    assert behind >= 10 and contradiction >= 10 and absurd >= 10, (behind, contradiction, absurd)


@pytest.mark.parametrize(
    ("removed", "expected"),
    [
        (Predicate("Car", (), Extreme.NEAREST), (0, 1)),
        (Predicate("Car", (), Extreme.FARTHEST), (0, 2)),
        (Predicate("Car", (OnSide(Side.RIGHT),)), (0,)),
        (Predicate("Car", (MotionState(False),)), (0, 1)),
    ],
)
def test_exclusion_is_base_minus_removed(removed, expected):
    res = _resolve(Exclusion(Predicate("Car"), removed), hand_world())
    assert res.ids == expected and res.crisp


def test_exclusion_rejects_an_empty_or_total_cut_and_bad_shapes():
    # No car is in our lane: nothing is cut, so "all the cars except the ones ahead" is not crisp.
    assert not _resolve(
        Exclusion(Predicate("Car"), Predicate("Car", (OnSide(Side.AHEAD),))), hand_world()
    ).crisp
    with pytest.raises(ValueError):
        Exclusion(Predicate("Car"), Predicate("Pedestrian", (), Extreme.NEAREST))
    with pytest.raises(ValueError):
        Exclusion(Predicate("Car", (), Extreme.NEAREST), Predicate("Car"))


@pytest.mark.parametrize(
    ("extreme", "rank", "expected"),
    [
        (Extreme.NEAREST, 2, 0),  # depths 9.75 (2), 17.75 (0), 27.75 (1)
        (Extreme.NEAREST, 3, 1),
        (Extreme.FARTHEST, 2, 0),
        (Extreme.LEFTMOST, 2, 1),  # y 3.5 (0), -3.5 (1), -5 (2)
        (Extreme.RIGHTMOST, 3, 0),
        (Extreme.FASTEST, 2, 1),  # 10 m/s (0), 8 m/s (1), parked (2)
    ],
)
def test_ordinal_ranks_by_the_superlative(extreme, rank, expected):
    res = _resolve(Ordinal(Predicate("Car"), extreme, rank), hand_world())
    assert res.ids == (expected,) and res.crisp


def test_ordinal_needs_clear_gaps_and_enough_members():
    close = [
        make_actor(0, "Car", 10.0, -3.0, 0.0, (0.0, 0.0), CAR),
        make_actor(1, "Car", 20.0, -3.0, 0.0, (0.0, 0.0), CAR),
        make_actor(2, "Car", 20.5, 3.0, 0.0, (0.0, 0.0), CAR),
    ]
    assert not _resolve(Ordinal(Predicate("Car"), Extreme.NEAREST, 2), close).crisp
    assert _resolve(Ordinal(Predicate("Car"), Extreme.NEAREST, 4), close).ids == ()
    # Second fastest among cars where the second is parked: not crisp.
    assert not _resolve(Ordinal(Predicate("Car"), Extreme.FASTEST, 3), hand_world()).crisp
    with pytest.raises(ValueError):
        Ordinal(Predicate("Car"), Extreme.NEAREST, 1)


def test_slowest_ranks_the_moving_only_and_is_crisp_only_among_movers():
    movers = [
        make_actor(0, "Car", 10.0, -3.0, 0.0, (10.0, 0.0), CAR),
        make_actor(1, "Car", 20.0, -3.0, 0.0, (3.0, 0.0), CAR),
        make_actor(2, "Car", 30.0, 3.0, 0.0, (6.0, 0.0), CAR),
    ]
    assert analyse(Predicate("Car", (), Extreme.SLOWEST), movers).ids == (1,)
    second = _resolve(Ordinal(Predicate("Car"), Extreme.SLOWEST, 2), movers)
    assert second.ids == (2,) and second.crisp
    # a parked car is not the slowest, and makes "slowest" unclear (it might be said to be)
    parked = [*movers, make_actor(3, "Car", 40.0, 3.0, 0.0, (0.0, 0.0), CAR)]
    res = analyse(Predicate("Car", (), Extreme.SLOWEST), parked)
    assert res.ids == (1,) and not res.crisp
    assert not _resolve(Ordinal(Predicate("Car"), Extreme.SLOWEST, 2), parked).crisp
    # the base generator never says it; the extended one does
    assert Extreme.SLOWEST not in BASE_EXTREMES and Extreme.SLOWEST.tag == "velocity"


def test_an_ordinal_over_every_class_ranks_all_referable_actors():
    res = _resolve(Ordinal(Predicate(None), Extreme.NEAREST, 3), hand_world())
    assert res.ids == (4,) and res.crisp  # depths 7.7 (3), 9.75 (2), 14.7 (4), 17.75 (0)


def test_extended_ordinals_say_slowest_and_any_class(extended):
    ordinals = [p for _, prompts in extended for p in prompts if p.family == "ordinal"]
    assert any(p.expression.extreme is Extreme.SLOWEST for p in ordinals)
    assert any(p.expression.base.cls is None for p in ordinals)
    for p in ordinals:
        if p.expression.extreme is Extreme.SLOWEST:
            assert "slow" in p.text.lower() or "lowest speed" in p.text.lower(), p.text


def _street() -> list:
    """A cyclist (20, 0) with a car right behind it (27, 0.5) and one far behind (45, 0); a
    pedestrian next to the cyclist (21, 2.5); two parked cars (10, 6) and (30, 6) with a
    pedestrian between them (20, 6.5); a pedestrian at (12, -6)."""
    return [
        make_actor(0, "Cyclist", 20.0, 0.0, 0.0, (4.0, 0.0), CYC),
        make_actor(1, "Car", 27.0, 0.5, 0.0, (4.0, 0.0), CAR),
        make_actor(2, "Car", 45.0, 0.0, 0.0, (4.0, 0.0), CAR),
        make_actor(3, "Pedestrian", 21.0, 2.5, 0.0, (0.0, 0.0), PED),
        make_actor(4, "Pedestrian", 20.0, 6.5, 0.0, (0.0, 0.0), PED),
        make_actor(5, "Pedestrian", 12.0, -6.0, 0.0, (0.0, 0.0), PED),
    ]


def test_relations_have_their_documented_meaning():
    w = _street()
    cyclist = Predicate("Cyclist")
    # behind: near edge beyond the cyclist's far edge (20.9) by at most 15 m, |dy| <= 2
    assert _resolve(Related(Predicate("Car"), Relation.BEHIND, cyclist), w).ids == (1,)
    # next to: centre distance <= 4 m
    assert _resolve(Related(Predicate("Pedestrian"), Relation.NEXT_TO, cyclist), w).ids == (3,)
    # closest to: the smallest centre distance, runner-up >= 1 m farther
    res = _resolve(Related(Predicate("Pedestrian"), Relation.CLOSEST_TO, cyclist), w)
    assert res.ids == (3,) and res.crisp
    # between the two cars: none (the cars are moving, the parked pair is below)
    two_parked = [
        *w[:1],
        make_actor(1, "Car", 10.0, 6.0, 0.0, (0.0, 0.0), CAR),
        make_actor(2, "Car", 30.0, 6.0, 0.0, (0.0, 0.0), CAR),
        *w[3:],
    ]
    res = _resolve(Related(Predicate("Pedestrian"), Relation.BETWEEN, Predicate("Car")), two_parked)
    assert res.ids == (4,) and res.crisp
    # the reference must be unique: two cars are not "the car"
    assert (
        _resolve(Related(Predicate("Pedestrian"), Relation.CLOSEST_TO, Predicate("Car")), w).ids
        == ()
    )


def test_relation_crispness():
    w = _street()
    w[3] = make_actor(3, "Pedestrian", 20.0, 3.9, 0.0, (0.0, 0.0), PED)  # 3.9 m from the cyclist
    assert not _resolve(
        Related(Predicate("Pedestrian"), Relation.NEXT_TO, Predicate("Cyclist")), w
    ).crisp
    w[4] = make_actor(4, "Pedestrian", 20.0, -4.4, 0.0, (0.0, 0.0), PED)  # 4.4 m: closest tie
    assert not _resolve(
        Related(Predicate("Pedestrian"), Relation.CLOSEST_TO, Predicate("Cyclist")), w
    ).crisp


def test_count_is_the_counted_set_and_count_questions_are_detected():
    assert _resolve(Count(Predicate("Car", (MotionState(False),))), hand_world()).ids == (2,)
    assert (
        _resolve(Count(Predicate("Cyclist", (HeadingIs(Heading.APPROACHING),))), hand_world()).ids
        == ()
    )
    for text in ("How many cars are parked?", "count the cyclists", "NUMBER OF PEDESTRIANS?"):
        assert is_count_question(text)
    for text in ("the third car counting from the left", "the cars", "a countdown sign"):
        assert not is_count_question(text)


def test_direction_of_travel():
    from scenes.language.prompts.families import Direction, Travel

    w = hand_world()  # car 0 drives away along +x, car 1 comes along -x, cyclist 5 along +x
    assert analyse(Predicate(None, (Travel(Direction.SAME),)), w).ids == (0, 5)
    assert analyse(Predicate("Car", (Travel(Direction.OPPOSITE),)), w).ids == (1,)
    # The crossing pedestrian (velocity along -y) travels neither way.
    assert analyse(Predicate("Pedestrian", (Travel(Direction.SAME),)), w).ids == ()
    diagonal = [make_actor(0, "Car", 20.0, 0.0, 0.0, (3.0, 2.0), CAR)]  # 33.7 degrees off +x
    assert not analyse(Predicate("Car", (Travel(Direction.SAME),)), diagonal).crisp
    for text in ("the cars heading the same way as us", "cyclists coming the other way"):
        assert infer_tags(text) == {"class", "motion"}
    assert infer_tags("the car on the opposite side") == {"class", "position"}


# ---------------------------------------------------------------------------------------------
# Base unchanged
# ---------------------------------------------------------------------------------------------

# sha256 of the prompts below, computed with main's generator before the extended language
# (commit df5a9e6); the base language must give the same prompts for the same seeds.
BASE_DIGEST = "6f8e46e6dd022149d09a5c3a03423960a9333f50885c4ec3e3817f0dba9c7321"


def test_base_language_prompts_are_unchanged():
    h = hashlib.sha256()
    worlds = random_worlds(7, 40)
    for phrasing in ("train", "heldout", "all"):
        for geometry in (False, True):
            cfg = PromptConfig(phrasing=phrasing, geometry_only=geometry)
            rng = np.random.default_rng(123)
            for w in worlds:
                for p in generate_prompts(w, rng, 6, config=cfg):
                    line = f"{p.text}|{p.referent_ids}|{sorted(p.tags)}|{p.variants}\n"
                    h.update(line.encode())
    assert h.hexdigest() == BASE_DIGEST
    with pytest.raises(ValueError, match="language"):
        PromptConfig(language="other")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------
# perturb
# ---------------------------------------------------------------------------------------------

_KEEP = re.compile(
    r"^(?:not|no|isn't|aren't|never|except|but|besides|excluding|second|third|2nd|3rd|how|many"
    r"|count|left|right|twenty|five|half|\d+(?:\.\d+)?)$"
)


def _kept_words(text: str) -> list[str]:
    return [
        w
        for w in re.findall(r"[a-z0-9'.]+", text.lower().rstrip(".!?"))
        if _KEEP.match(w.strip("."))
    ]


def test_perturb_keeps_negators_numbers_ordinals_and_class_nouns():
    texts = [
        "Show me the cars that are not moving.",
        "all the pedestrians except the nearest one",
        "The second closest cyclist about 20 m ahead isn't on the left",
        "How many cars are parked within twenty-five metres?",
        "the cyclists no faster than 15 km/h, half a metre to the right",
    ]
    rng = np.random.default_rng(0)
    changed = 0
    for k in range(1000):
        text = texts[k % len(texts)]
        out = perturb(text, rng)
        changed += out != text
        assert out.strip()
        assert _kept_words(out) == _kept_words(text), (text, out)
        # Class nouns are never dropped (a swap or a typo keeps the word's place).
        nouns = len(re.findall(r"\b(?:cars?|pedestrians?|cyclists?)\b", text.lower()))
        dropped = len(text.split()) - len(out.split())
        droppable = len(re.findall(r"\b(?:the|a|an|that|are|is)\b", text.lower()))
        assert 0 <= dropped <= droppable, (text, out)
        assert nouns >= 1
    assert changed > 500


def test_p_perturb_rewrites_texts_and_keeps_referents():
    world = random_worlds(3, 1)[0]
    for language in ("base", "extended"):
        plain = generate_prompts(
            world, np.random.default_rng(4), 8, config=PromptConfig(language=language)
        )
        noisy = generate_prompts(
            world,
            np.random.default_rng(4),
            8,
            config=PromptConfig(language=language, p_perturb=1.0),
        )
        assert [p.referent_ids for p in noisy] == [p.referent_ids for p in plain]
        assert [p.tags for p in noisy] == [p.tags for p in plain]
        assert any(a.text != b.text for a, b in zip(plain, noisy, strict=True))


# ---------------------------------------------------------------------------------------------
# Extended generation
# ---------------------------------------------------------------------------------------------


def _extended(seed: int = 5, count: int = 40, per: int = 10):
    cfg = PromptConfig(language="extended")
    rng = np.random.default_rng(seed)
    return [(w, generate_prompts(w, rng, per, config=cfg)) for w in random_worlds(seed, count)]


@pytest.fixture(scope="module")
def extended():
    return _extended()


def test_extended_generates_every_family_with_exact_referents(extended):
    families = Counter()
    for world, prompts in extended:
        feats = actor_features(world)
        texts = [p.text.lower().rstrip(".!?") for p in prompts]
        assert len(set(texts)) == len(texts)
        for p in prompts:
            families[p.family] += 1
            assert p.text.strip() and len(p.text.split()) <= 22
            assert is_count_question(p.text) == (p.family == "count"), p.text
            assert not set(p.variants) & HELDOUT_VARIANTS, p.text  # the train stream
            if p.family == "out_of_class":
                assert p.referent_ids == () and p.predicate is None
            elif p.expression is not None:
                res = p.expression.analyse(feats, DEFAULT_REGION)
                assert res.ids == p.referent_ids and res.crisp and not res.conflicts
            else:
                res = analyse(p.predicate, world)
                assert res.ids == p.referent_ids and not res.conflicts
            if p.family == "unsatisfiable":
                assert p.referent_ids == ()
                assert unsatisfiable(p.predicate, feats, DEFAULT_REGION)
            if p.family in ("negation", "exclusion", "ordinal", "relation", "attribute"):
                assert p.referent_ids
    assert set(families) == {
        "attribute",
        "out_of_class",
        "unsatisfiable",
        "negation",
        "exclusion",
        "ordinal",
        "relation",
        "count",
    }, families


def test_extended_tags_follow_the_predicate(extended):
    for _, prompts in extended:
        for p in prompts:
            if p.family in ("attribute", "negation", "unsatisfiable", "count"):
                inferred = infer_tags(p.text)
                # The base reading of "N m ... in front of us" also counts as a position.
                if re.search(r"\bin front of\b", p.text.lower()):
                    inferred -= {"position"} - p.tags
                assert p.tags == p.predicate.tags == inferred, p.text
            else:
                assert p.tags == infer_tags(p.text), p.text


def test_extended_never_says_the_lane_as_in_front_of_us(extended):
    from scenes.language.prompts.render import _CHOICES

    for phrasing in ("train", "heldout", "all"):
        lane = _CHOICES[("extended", phrasing)]["position.ahead"]
        assert lane.allowed and not [t for t in lane.allowed + lane.heldout if "front" in t]
    for _, prompts in extended:
        for p in prompts:
            if p.family == "attribute" and re.search(r"\bin front of\b", p.text.lower()):
                assert "depth" in p.predicate.tags, p.text


def test_extended_flips(extended):
    for world, prompts in extended[:10]:
        fw = actor_features(flip_world(world))
        for p in prompts:
            fp = p.flipped()
            assert flip_left_right(fp.text) == p.text
            if fp.expression is not None:
                assert fp.expression.analyse(fw, DEFAULT_REGION).ids == p.referent_ids, p.text


def test_out_of_class_nouns_name_no_class():
    assert len(OUT_OF_CLASS) >= 300
    for entry in OUT_OF_CLASS:
        singular, plural = entry.split("|")
        assert not re.search(
            r"\b(?:cars?|pedestrians?|cyclists?|persons?|people|vans?|taxis?)\b", entry
        ), entry
        assert singular != plural or singular in ("sheep", "deer", "fish")


def test_out_of_class_nouns_split_between_the_streams():
    from scenes.language.prompts.nouns import HELDOUT_NOUNS, nouns_for

    assert 0.25 < len(HELDOUT_NOUNS) / len(OUT_OF_CLASS) < 0.4
    assert set(nouns_for("train")) | set(nouns_for("heldout")) == set(OUT_OF_CLASS)
    assert not set(nouns_for("train")) & HELDOUT_NOUNS
    world = random_worlds(2, 1)[0]
    for phrasing, heldout in (("train", False), ("heldout", True)):
        cfg = PromptConfig(
            language="extended",
            phrasing=phrasing,
            family_rates=(1, 0, 0, 0, 0, 0, 0),
            p_nonsense=0.0,
        )
        prompts = generate_prompts(world, np.random.default_rng(0), 30, config=cfg)
        assert len(prompts) >= 20 and all(p.family == "out_of_class" for p in prompts)
        for p in prompts:
            assert (p.variants[0][len("ooc:") :] in HELDOUT_NOUNS) == heldout, p.text


def test_synth_writes_and_reads_an_extended_root(tmp_path):
    from scenes.synth.generate import SynthSettings, main
    from scenes.talk2radar.root import Talk2RadarRoot

    out = tmp_path / "root"
    args = ["--out", str(out), "--frames", "8", "--prompts-per-world", "8", "--seed", "1"]
    assert main([*args, "--language", "extended", "--no-camera", "--quiet"]) == 0
    assert "language" not in SynthSettings().key()
    assert SynthSettings(language="extended").key()["language"] == "extended"
    root = Talk2RadarRoot(out)
    empty = 0
    for split in root.splits():
        for sid in root.ids(split):
            sample = root.load(sid)
            meta = root.load_meta(sid)
            assert len(sample.boxes) == len(meta.referent_ids)
            empty += len(meta.referent_ids) == 0
    assert empty >= 1
