"""Command phrasing (issue 40 item 4): driving instructions around single-referent descriptions.

The generator's default output must not move (a tiny root pinned with main's generator before the
option existed, ``tests/synth_pins.py``); commands keep their description's referents; the
held-out command templates never reach the train stream; templates fit the referent's class and
motion.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from model.training.config import parse_args as train_args
from scenes.geometry.classes import NUSCENES
from scenes.language.prompts import PromptConfig, as_command, generate_prompts
from scenes.language.prompts.commands import (
    COMMAND_HELDOUT,
    COMMAND_SLOTS,
    COMMAND_TRAIN,
    command_templates,
    noun_phrase_of,
)
from scenes.language.prompts.phrasing.split import variant_id
from scenes.synth.generate import main as synth_main
from tests.scenes.language.prompt_helpers import random_worlds
from tests.synth_pins import TINY_ROOT, differences


@pytest.mark.parametrize("extra", [[], ["--command-share", "0", "--sensors", "vod"]])
def test_default_generator_output_is_unchanged(tmp_path, extra):
    assert synth_main(["--out", str(tmp_path / "r"), *TINY_ROOT, *extra]) == 0
    changed = differences(tmp_path / "r", "tiny")
    assert not changed, "\n".join(changed[:8])


def _stream(config: PromptConfig, seed: int = 3, n_worlds: int = 120):
    out = []
    for k, world in enumerate(random_worlds(seed, n_worlds)):
        out.append(
            (world, generate_prompts(world, np.random.default_rng([seed, k]), 6, config=config))
        )
    return out


def test_commands_keep_their_descriptions_referents_exactly():
    plain = _stream(PromptConfig())
    wrapped = _stream(PromptConfig(command_share=1.0))
    n_commands = 0
    for (_, ps), (_world, cs) in zip(plain, wrapped, strict=True):
        assert len(ps) == len(cs)
        for p, c in zip(ps, cs, strict=True):
            assert c.referent_ids == p.referent_ids and c.predicate == p.predicate
            assert c.tags == p.tags
            if len(p.referent_ids) != 1:
                assert c.text == p.text  # only single-referent prompts become commands
                continue
            if c.text == p.text:
                continue  # too long as a command: kept as the description
            n_commands += 1
            assert noun_phrase_of(p.text) in c.text, (p.text, c.text)
            assert c.variants[-1].startswith("command:")
    assert n_commands > 200


def test_command_share_is_a_share_of_single_referent_prompts():
    half = _stream(PromptConfig(command_share=0.5))
    single = [p for _, ps in half for p in ps if len(p.referent_ids) == 1]
    commands = [p for p in single if p.variants and p.variants[-1].startswith("command:")]
    assert 0.35 < len(commands) / len(single) < 0.65


def test_heldout_templates_never_in_the_train_stream_and_used_by_the_heldout_one():
    assert COMMAND_TRAIN.isdisjoint(COMMAND_HELDOUT) and len(COMMAND_HELDOUT) >= 10
    assert len(COMMAND_TRAIN) + len(COMMAND_HELDOUT) >= 60  # dozens of wordings
    for cls in ("Car", "Pedestrian", "Cyclist", None):
        for moving in (True, False, None):
            ids = {vid for vid, _ in command_templates("train", cls, moving)}
            assert ids and ids <= COMMAND_TRAIN
    train = _stream(PromptConfig(command_share=1.0))
    used = {p.variants[-1] for _, ps in train for p in ps if p.variants}
    used = {v for v in used if v.startswith("command:")}
    assert used and used <= COMMAND_TRAIN
    assert len(used) > 40
    held = _stream(PromptConfig(command_share=1.0, phrasing="heldout"), n_worlds=60)
    used_held = {p.variants[-1] for _, ps in held for p in ps if p.variants}
    used_held = {v for v in used_held if v.startswith("command:")}
    assert used_held and used_held <= COMMAND_HELDOUT


def _template_of(vid: str) -> str:
    return vid.split(":", 1)[1]


def test_templates_fit_the_referents_class_and_motion():
    seen_cross = 0
    for world, ps in _stream(PromptConfig(command_share=1.0, phrasing="all")):
        by_id = {a.actor_id: a for a in world}
        for p in ps:
            if not (p.variants and p.variants[-1].startswith("command:")):
                continue
            actor = by_id[p.referent_ids[0]]
            template = _template_of(p.variants[-1])
            moving = float(np.hypot(*actor.velocity[:2])) > 0.5
            if "to cross" in template or "walk" in template:
                seen_cross += 1
                assert actor.cls == "Pedestrian", p.text
            if re.match(r"overtake \{np\}$|pass \{np\}$", template):
                assert actor.cls in ("Car", "Cyclist") and moving, p.text
            if template in ("let {np} pass", "tail {np}"):
                assert moving, p.text
            if template in ("park behind {np} and wait", "drive around {np}"):
                assert not moving, p.text
    assert seen_cross > 0
    # Unknown class: no class-specific template, no pronoun.
    for vid, text in command_templates("all", None, None):
        assert "{it}" not in text and "to cross" not in text
        assert vid in {
            variant_id("command/any", t)
            for t in COMMAND_SLOTS["command/any"].core + COMMAND_SLOTS["command/any"].more
        }


def test_road_user_commands_fit_their_class_and_motion():
    """The nuscenes class set's command templates: each drawn, each only where it fits."""
    config = PromptConfig(command_share=1.0, phrasing="all", classes="nuscenes")
    used = set()
    for k, world in enumerate(random_worlds(5, 300, "nuscenes")):
        by_id = {a.actor_id: a for a in world}
        for p in generate_prompts(world, np.random.default_rng([5, k]), 6, config=config):
            if not (p.variants and p.variants[-1].startswith("command:")):
                continue
            actor = by_id[p.referent_ids[0]]
            template = _template_of(p.variants[-1])
            used.add(template)
            moving = actor.speed > 0.5
            if template == "let {np} pull out":
                assert actor.cls == "Bus" and not moving, p.text
            if template in ("steer around {np}", "slow down near {np}"):
                assert actor.cls in ("TrafficCone", "Barrier"), p.text
            if re.match(r"overtake \{np\}$|pass \{np\}$", template):
                assert moving and actor.cls not in ("TrafficCone", "Barrier", "Pedestrian"), p.text
    new = {"give {np} some space", "let {np} pull out", "let {np} get ahead"}
    new |= {"steer around {np}", "slow down near {np}"}
    assert len(new & used) >= 3, new & used
    # Where each may be drawn, exactly.
    fits = {
        "let {np} pull out": {("Bus", False)},
        "let {np} get ahead": {("Motorcycle", True)},
        "give {np} some space": {("Bus", False), ("Bus", True)},
        "steer around {np}": {(c, m) for c in ("TrafficCone", "Barrier") for m in (False, True)},
    }
    for template, where in fits.items():
        for cls in NUSCENES.names:
            for moving in (False, True):
                offered = {t for _, t in command_templates("all", cls, moving)}
                assert (template in offered) == ((cls, moving) in where), (template, cls, moving)


@pytest.mark.parametrize(
    ("description", "noun_phrase"),
    [
        ("Show me the parked car on the left.", "the parked car on the left"),
        ("where is the cyclist riding towards us?", "the cyclist riding towards us"),
        ("THE PEDESTRIAN ABOUT 20 M AHEAD", "the pedestrian about 20 m ahead"),
        ("The Car On The Right", "the car on the right"),
        ("the nearest car please", "the nearest car"),
        ("can you locate the car approaching us?", "the car approaching us"),
        ("tell me where the farthest cyclist is", "the farthest cyclist"),
        ("The car moving away from us.", "the car moving away from us"),
    ],
)
def test_as_command_wraps_the_descriptions_noun_phrase(description, noun_phrase):
    assert noun_phrase_of(description) == noun_phrase
    rng = np.random.default_rng(0)
    texts = {as_command(description, rng, cls="Pedestrian", moving=False) for _ in range(30)}
    assert len(texts) > 10
    for text in texts:
        assert noun_phrase in text
        assert text.lower().rstrip(".") != noun_phrase
    with pytest.raises(ValueError, match="phrasing"):
        as_command(description, rng, "nope")
    with pytest.raises(ValueError, match="empty"):
        as_command("  ", rng)


def test_as_command_is_deterministic_and_respects_the_stream():
    a = [as_command("the car", np.random.default_rng(5), "train", cls="Car") for _ in range(3)]
    assert len(set(a)) == 1
    rng = np.random.default_rng(1)
    heldout_texts = {
        t.replace("{np}", "the car") for _, t in command_templates("heldout", "Car", True)
    }
    for _ in range(40):
        text = as_command("the car", rng, "heldout", cls="Car", moving=True)
        assert text.rstrip(".")[:1].lower() + text.rstrip(".")[1:] in heldout_texts


def test_command_share_flags_reach_the_generator(tmp_path):
    cfg, _ = train_args(["--data", "x", "--out", str(tmp_path / "run"), "--command-share", "0.3"])
    assert cfg.prompt_draw().config.command_share == 0.3
    with pytest.raises(ValueError, match="probability"):
        PromptConfig(command_share=1.5)
    root = tmp_path / "c"
    args = ["--out", str(root), "--frames", "4", "--seed", "7", "--no-camera", "--quiet"]
    assert synth_main([*args, "--command-share", "1"]) == 0
    texts = [
        p.read_text().strip() for p in sorted((root / "lidar" / "training" / "prompt").glob("*"))
    ]
    assert texts
    assert (
        synth_main(["--out", str(tmp_path / "bad"), "--frames", "1", "--command-share", "2"]) == 2
    )


def test_suite_commands_are_hand_typed_not_the_templates_and_come_in_pairs():
    import json

    from bench.studies.language_cases import SUITE_FILE, SuiteError, load_suite, parse_suite

    suite = load_suite()
    commands = [s for s in suite.sentences if s.family == "command"]
    descriptions = {s.id: s for s in suite.sentences if s.family == "command_description"}
    assert len(commands) >= 40 and len(descriptions) == len(commands)
    templates = [
        re.compile(
            "^"
            + re.escape(t).replace(re.escape("{np}"), ".+").replace(re.escape("{it}"), r"\w+")
            + r"\.?$"
        )
        for slot in COMMAND_SLOTS.values()
        for t in slot.core + slot.more
    ]
    for s in commands:
        assert not any(t.match(s.text.lower()) for t in templates), s.text
        twin = descriptions[s.id + "-desc"]
        assert twin.query == s.query
    data = json.loads(SUITE_FILE.read_text(encoding="utf-8"))
    lone = [e for e in data["sentences"] if e["id"] != "cmd-01-desc"]
    with pytest.raises(SuiteError, match="command cmd-01 needs a command_description cmd-01-desc"):
        parse_suite(dict(data, sentences=lone), "suite.json")
