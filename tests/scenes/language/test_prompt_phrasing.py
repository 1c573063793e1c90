"""Tests for scenes.language.prompts' phrasing variants: coverage, the train / held-out split, truth of
every variant (counts, numbers, tags, flips) in both streams, and the typed forms of infer_tags."""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from scenes.geometry.classes import NUSCENES
from scenes.language.prompts import (
    HELDOUT_VARIANTS,
    TRAIN_VARIANTS,
    DepthBetween,
    Predicate,
    PromptConfig,
    analyse,
    flip_left_right,
    generate_prompts,
    infer_tags,
    render_with_variants,
    spell_number,
)
from scenes.language.prompts.numbers import NUMBER_STYLES
from scenes.language.prompts.phrasing.slots import SLOTS
from scenes.language.prompts.phrasing.split import group_of, variant_id
from tests.scenes.language.prompt_helpers import (
    WORD_VALUES,
    flip_world,
    has_phrase,
    is_plural,
    parse_number,
    random_worlds,
    read_numbers,
)

ALL_IDS = {variant_id(name, t) for name, slot in SLOTS.items() for t in slot.core + slot.more}
# Turn every choice up so that a few thousand prompts reach every variant.
EVERYTHING = PromptConfig(
    phrasing="all", p_extreme=0.35, p_adjective=0.5, p_frame=0.6, p_restyle=0.6, p_number_words=0.5
)


def _stream(config: PromptConfig, seed: int, n_worlds: int, per_world: int = 8):
    out = []
    for k, world in enumerate(random_worlds(seed, n_worlds, config.classes)):
        prompts = generate_prompts(
            world, np.random.default_rng([seed, k]), per_world, config=config
        )
        out.append((world, prompts))
    return out


@pytest.fixture(scope="module")
def streams():
    """Prompts of the train and heldout streams on the same worlds and rng states, and an
    ``all`` stream with every choice turned up."""
    out = {"train": _stream(PromptConfig(), 1, 260)}
    out["heldout"] = _stream(PromptConfig(phrasing="heldout"), 1, 150)
    out["everything"] = _stream(EVERYTHING, 2, 250)
    # The nuscenes class set's road users: their nouns, verbs and motion words.
    out["road_users"] = _stream(replace(EVERYTHING, classes="nuscenes"), 3, 250)
    return out


def _prompts(streams, *names):
    return [(w, p) for name in names for w, ps in streams[name] for p in ps]


# ---------------------------------------------------------------------------------------------
# The split
# ---------------------------------------------------------------------------------------------


def test_split_is_disjoint_complete_and_keeps_core_in_train():
    assert not TRAIN_VARIANTS & HELDOUT_VARIANTS
    assert TRAIN_VARIANTS | HELDOUT_VARIANTS == ALL_IDS
    for name, slot in SLOTS.items():
        assert {variant_id(name, t) for t in slot.core} <= TRAIN_VARIANTS, name
        if slot.more:  # every group with extra variants holds at least one out
            assert any(i.startswith(group_of(name) + ":") for i in HELDOUT_VARIANTS), name
    share = len(HELDOUT_VARIANTS) / sum(len(s.more) for s in SLOTS.values())
    assert 0.25 < share < 0.5, share
    # Left and right share their templates, so a flip never crosses the split.
    for t in SLOTS["position.side"].core + SLOTS["extreme.lateral"].more:
        assert not re.search(r"\b(left|right)", t), t


def test_phrasing_values_are_checked():
    with pytest.raises(ValueError, match="phrasing"):
        PromptConfig(phrasing="test")
    with pytest.raises(ValueError, match="p_frame"):
        PromptConfig(p_frame=1.5)


# ---------------------------------------------------------------------------------------------
# Every variant is used, and the recorded variants are in the text
# ---------------------------------------------------------------------------------------------

_KEY_CHECKS = {
    "case:sentence case": lambda t: not t[:1].islower(),
    "case:lower case": lambda t: t == t.lower(),
    "case:upper case": lambda t: t == t.upper(),
    "case:title case": lambda t: all(not w[:1].islower() for w in t.split()),
    "end:period": lambda t: t.endswith("."),
    "end:exclamation mark": lambda t: t.endswith("!"),
    "end:question mark": lambda t: t.endswith("?"),
    "end:no punctuation": lambda t: t[-1:] not in ".!?",
    "joiner:comma": lambda t: ", " in t,
    "joiner:and": lambda t: " and " in t.lower(),
    "joiner:space": lambda t: True,
    "number:digits": lambda t: re.search(r"\d", t) is not None,
    # A word, not a digit, right before a spelled-out unit ("twenty metres", "half a metre").
    "number:hyphenated words": lambda t: re.search(r"[a-z] (?:kilo)?met(?:er|re)", t.lower()),
    "number:spaced words": lambda t: re.search(r"[a-z] (?:kilo)?met(?:er|re)", t.lower()),
    "count:words": lambda t: re.search(r"\d", t) is None or read_numbers(t)[1] != [],
    "count:digits": lambda t: re.search(r"\b\d+\b", t) is not None,
}


def _literal_parts(template: str) -> list[str]:
    parts = re.split(r"\{\w+\}", template.rstrip("?"))
    return [p.strip() for p in parts if p.strip()]


def _singular(text: str) -> str:
    return re.sub(r"\b(\w*met(?:er|re))s\b", r"\1", text)


def _variant_in_text(vid: str, text: str) -> bool:
    if vid in _KEY_CHECKS:
        return bool(_KEY_CHECKS[vid](text))
    group, template = vid.split(":", 1)
    low = _singular(text.lower())
    template = _singular(template)
    if group.startswith("noun."):
        return any(has_phrase(low, form) for form in template.split("|"))
    if group.startswith("unit.") and not template.startswith("{x} "):
        return re.search(r"\d" + re.escape(template[3:]), low) is not None
    return all(p in low for p in _literal_parts(template.replace("{side}", "left"))) or all(
        p in low for p in _literal_parts(template.replace("{side}", "right"))
    )


def test_every_variant_appears_and_records_are_true(streams):
    used: Counter[str] = Counter()
    for _, p in _prompts(streams, "train", "heldout", "everything", "road_users"):
        assert p.variants, p.text
        for vid in p.variants:
            assert _variant_in_text(vid, p.text), (vid, p.text)
        used.update(p.variants)
    missing = sorted(ALL_IDS - set(used))
    assert not missing, missing


def test_no_heldout_variant_in_the_train_stream(streams):
    train = _prompts(streams, "train")[:2000]
    assert len(train) == 2000
    train_text = " | ".join(p.text.lower() for _, p in train)
    for _, p in train:
        assert not set(p.variants) & HELDOUT_VARIANTS, (p.text, set(p.variants) & HELDOUT_VARIANTS)
    # Read from the text too: held-out words that no train variant contains never occur.
    egos = [i.split(":", 1)[1] for i in TRAIN_VARIANTS if i.startswith("ego:")]
    train_words = " | ".join(
        i.split(":", 1)[1].replace("{side}", side).replace("{us}", ego)
        for i in TRAIN_VARIANTS
        for side in ("left", "right")
        for ego in egos
    )
    checked = 0
    for vid in HELDOUT_VARIANTS:
        group, template = vid.split(":", 1)
        if group.startswith("noun."):
            parts = template.split("|")
        elif vid in _KEY_CHECKS or group.startswith("unit."):
            continue
        else:
            parts = [max(_literal_parts(template), key=len, default="")]
        for part in parts:
            if part and not has_phrase(train_words, part):
                assert not has_phrase(train_text, part), (vid, part)
                checked += 1
    assert checked >= 20, checked
    assert "!" not in train_text
    assert not re.search(r"\d(?:m\b(?!/)|km/h)", train_text)


def test_heldout_stream_uses_a_heldout_variant_in_every_sentence(streams):
    heldout = _prompts(streams, "heldout")
    assert len(heldout) > 1000
    for _, p in heldout:
        assert set(p.variants) & HELDOUT_VARIANTS, p.text


def test_streams_say_the_same_predicates(streams):
    """One rng state gives the same predicates in the train and heldout wordings."""
    same = total = 0
    for (_, a), (_, b) in zip(streams["train"], streams["heldout"], strict=False):
        total += 1
        same += [p.predicate for p in a] == [p.predicate for p in b]
    assert same >= 0.9 * total, (same, total)


# ---------------------------------------------------------------------------------------------
# Every sentence of every stream stays true
# ---------------------------------------------------------------------------------------------


def _values(pred: Predicate) -> list[float]:
    out = []
    for a in pred.atoms:
        if isinstance(a, DepthBetween):
            out += [a.lo, a.hi]
        elif hasattr(a, "metres"):
            out.append(a.metres)
        elif hasattr(a, "value"):
            out.append(a.value)
    return sorted(out)


def test_counts_numbers_and_referents_agree(streams):
    n_word_numbers = 0
    for k, (world, p) in enumerate(_prompts(streams, "train", "heldout", "everything")):
        n = len(p.referent_ids)
        if k % 4 == 0:
            assert p.referent_ids == analyse(p.predicate, world).ids
        assert is_plural(p.text) == (n > 1), (n, p.text)
        assert not has_phrase(p.text, "is" if n > 1 else "are"), (n, p.text)
        quantities, counts = read_numbers(p.text)
        assert sorted(quantities) == _values(p.predicate), (p.text, p.predicate)
        assert all(c == n for c in counts), (n, p.text)
        n_word_numbers += any(w in p.text.lower().split() for w in WORD_VALUES)
    assert n_word_numbers > 200


def test_road_user_prompts_read_back_and_resolve(streams):
    """The nuscenes class set's prompts: their tags read back from the text when infer_tags is
    told the set (with the vod set a cone or a lorry is an out-of-class thing), their referents
    are exactly the actors of their class that match, and every class is talked about."""
    named: Counter[str] = Counter()
    for world, p in _prompts(streams, "road_users"):
        assert p.tags == p.predicate.tags == infer_tags(p.text, "nuscenes"), p.text
        assert analyse(p.predicate, world).ids == p.referent_ids, p.text
        by_id = {a.actor_id: a for a in world}
        if p.predicate.cls is not None:
            assert {by_id[i].cls for i in p.referent_ids} == {p.predicate.cls}, p.text
            named[p.predicate.cls] += 1
        # "the vehicle" is wider than a car among trucks and buses: never said of a car
        text = re.sub(r"\b(?:ego[- ]vehicle|our vehicle|my vehicle)\b", "", p.text.lower())
        assert p.predicate.cls != "Car" or not re.search(r"\bvehicles?\b", text), p.text
    assert set(named) == set(NUSCENES.names), named
    assert min(named.values()) > 0.05 * sum(named.values()), named


def test_tags_and_flips_in_every_stream(streams):
    for k, (world, p) in enumerate(_prompts(streams, "train", "heldout", "everything")):
        assert p.tags == p.predicate.tags == infer_tags(p.text), p.text
        fp = p.flipped()
        assert infer_tags(fp.text) == p.tags and flip_left_right(fp.text) == p.text, p.text
        if k % 10 == 0:
            assert analyse(fp.predicate, flip_world(world)).ids == p.referent_ids
            n = len(p.referent_ids)
            for phrasing in ("train", "heldout"):
                a = render_with_variants(
                    p.predicate, n, np.random.default_rng(k), phrasing=phrasing
                )
                b = render_with_variants(
                    p.predicate.flipped(), n, np.random.default_rng(k), phrasing=phrasing
                )
                assert b == (flip_left_right(a[0]), a[1])


# ---------------------------------------------------------------------------------------------
# Numbers in words
# ---------------------------------------------------------------------------------------------


def test_number_words_parse_back():
    values = [float(v) for v in range(100)] + [v + 0.5 for v in range(20)] + [2.3, 0.7, 14.2]
    for style in NUMBER_STYLES:
        for v in values:
            text = spell_number(v, style)
            assert parse_number(text) == pytest.approx(v), (style, v, text)
    assert spell_number(25, "hyphenated words") == "twenty-five"
    assert spell_number(2.5, "hyphenated words") == "two and a half"
    assert spell_number(0.5, "hyphenated words") == "half a"
    assert spell_number(25, "spaced words") == "twenty five"
    assert spell_number(2.5, "spaced words") == "two point five"
    assert spell_number(120, "spaced words") == "120"  # words only below 100
    with pytest.raises(ValueError, match="style"):
        spell_number(3, "roman")


# ---------------------------------------------------------------------------------------------
# infer_tags on typed forms
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "tags"),
    [
        ("the car at fifteen kilometres per hour", {"class", "velocity"}),
        ("cars faster than 3 metres per second", {"class", "velocity"}),
        ("the bike going about half a metre per second", {"class", "velocity"}),
        ("the automobile doing 30kph", {"class", "velocity"}),
        ("people about twenty metres ahead", {"class", "depth"}),
        ("where is the person two and a half meters away", {"class", "depth"}),
        ("the cyclist 20m ahead", {"class", "depth"}),
        ("THE CAR FURTHEST TO THE LEFT", {"class", "position"}),
        ("the furthest car", {"class", "depth"}),
        ("show me the bikes heading our way", {"class", "motion"}),
        ("the automobiles at a standstill", {"class", "motion"}),
        ("the speediest bicyclist", {"class", "velocity"}),
        ("can you locate the thing in front of our car?", {"position"}),
    ],
)
def test_infer_tags_typed_forms(text, tags):
    assert infer_tags(text) == frozenset(tags)


# ---------------------------------------------------------------------------------------------
# scenes.synth --phrasing
# ---------------------------------------------------------------------------------------------


def test_synth_phrasing_option_says_the_same_prompts_in_other_words():
    from scenes.geometry.calib import sensor_to_lidar, vod_lidar_calibration, vod_radar_calibration
    from scenes.synth.generate import SynthError, SynthSettings, _parser, synthesize

    args = ["--out", "root", "--frames", "4"]
    assert _parser().parse_args(args).phrasing == "train"
    assert _parser().parse_args([*args, "--phrasing", "heldout"]).phrasing == "heldout"
    with pytest.raises(SystemExit):
        _parser().parse_args([*args, "--phrasing", "other"])
    with pytest.raises(SynthError, match="phrasing"):
        SynthSettings(phrasing="other")
    assert "phrasing" not in SynthSettings().key()  # roots written before the option resume
    assert SynthSettings(phrasing="heldout").key()["phrasing"] == "heldout"
    radar_to_lidar = sensor_to_lidar(vod_lidar_calibration(), vod_radar_calibration())
    frames = {
        p: synthesize(SynthSettings(phrasing=p, prompts_per_world=4), 0, radar_to_lidar)
        for p in ("train", "heldout")
    }
    train, heldout = frames["train"].prompts, frames["heldout"].prompts
    assert len(train) == len(heldout) > 0
    for a, b in zip(train, heldout, strict=True):
        assert (a.predicate, a.referent_ids) == (b.predicate, b.referent_ids)
        assert not set(a.variants) & HELDOUT_VARIANTS
        assert set(b.variants) & HELDOUT_VARIANTS
