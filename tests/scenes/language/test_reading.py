"""scenes.language.reading: people's sentences read down to what the model grounds, and the
generator's own sentences left exactly as they are (issue 49). The people's sentences here are
written for this test, in the ways people talk to a driver (a manoeuvre around the referent,
context first, no noun, colours and clothes, words the generator never writes)."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.geometry.classes import NUSCENES, VOD
from scenes.language.prompts import PromptConfig, generate_prompts
from scenes.language.reading import read_prompt
from scenes.synth.world import WorldConfig, generate_world

WORLDS = 12
"""Worlds the generator property test draws prompts over."""

PEOPLE = [
    # (sentence, class set, the texts grounded)
    ("park behind the grey van on the left", VOD, ("the car on the left",)),
    ("stay behind the cab in front of us", VOD, ("the car in front of us",)),
    ("pull over just before that taxi", VOD, ("the car",)),
    ("my sister is sitting in that jeep. stop next to it.", VOD, ("the car",)),
    ("the bus ahead is turning. follow it.", NUSCENES, ("the bus in front of us",)),
    ("can you pull up beside the lady in the yellow coat on the right?", VOD,
     ("the pedestrian on the right",)),
    ("that kid wants to cross. wait for him", VOD, ("the pedestrian",)),
    ("follow her", VOD, ("the pedestrian", "the cyclist")),
    ("let the semi on the right go first", NUSCENES, ("the truck on the right",)),
    ("drive slowly around the orange pylon", NUSCENES, ("the traffic cone",)),
    ("overtake the scooter", NUSCENES, ("the motorcycle",)),
    ("park the car behind the parked suv on the right", VOD, ("the parked car on the right",)),
    ("watch out, the worker next to the truck is walking onto the road", NUSCENES,
     ("the pedestrian next to the truck that is walking",)),
]  # fmt: skip


@pytest.mark.parametrize(("sentence", "classes", "texts"), PEOPLE)
def test_people_commands_are_read_down_to_their_referent(sentence, classes, texts) -> None:
    reading = read_prompt(sentence, classes)
    assert reading.texts == texts
    assert reading.command and reading.single


def test_vehicle_means_every_vehicle_class_of_the_set() -> None:
    reading = read_prompt("follow the white vehicle on the left", NUSCENES)
    assert "the truck on the left" in reading.texts and "the car on the left" in reading.texts
    assert "the pedestrian on the left" not in reading.texts
    assert read_prompt("follow the white vehicle on the left", VOD).texts == (
        "the car on the left",
    )


def test_a_class_the_set_lacks_is_named_not_guessed() -> None:
    reading = read_prompt("follow the bus", VOD)
    assert reading.missing == "bus" and reading.texts == ("the bus",)


def test_nonsense_and_things_keep_no_referent() -> None:
    assert read_prompt("asdf qwerty", VOD).texts == ("asdf qwerty",)
    fire = read_prompt("stop next to the fire hydrant", VOD)
    assert fire.texts == ("stop next to the fire hydrant",) and fire.missing


@pytest.mark.parametrize(
    ("sentence", "single"),
    [
        ("the cyclist closest to us", True),
        ("the second car on the left", True),
        ("the cars on the left", False),
        ("the two pedestrians ahead", False),
        ("all cars except the one on the left", False),
        ("both cyclists", False),
    ],
)
def test_number_of_a_description(sentence: str, single: bool) -> None:
    reading = read_prompt(sentence, VOD)
    assert reading.texts == (sentence,)  # the generator's words: grounded as written
    assert reading.single is single


@pytest.mark.parametrize("classes", ["vod", "nuscenes"])
def test_generator_sentences_are_read_as_written_and_commands_to_their_description(
    classes: str,
) -> None:
    """Every prompt the generator writes (extended language, every wording, half of the
    single-referent ones as commands, some of them the people's way): a description is grounded
    exactly as written; a command as the description inside it; a people's command as a command
    about an object of its referent's class; one object is meant only where one is referred to."""
    cs = VOD if classes == "vod" else NUSCENES
    config = PromptConfig(
        language="extended",
        phrasing="all",
        command_share=0.5,
        people_share=0.4,
        classes=classes,
    )
    seen = commands = people = 0
    for w in range(WORLDS):
        world = generate_world(np.random.default_rng(w), w, WorldConfig(classes=classes))
        rng = np.random.default_rng(100 + w)
        for prompt in generate_prompts(world.actors, rng, 12, config=config):
            reading = read_prompt(prompt.text, cs)
            is_command = any(v.startswith("command:") for v in prompt.variants)
            seen += 1
            if any(v.startswith("people:") for v in prompt.variants):
                # a people's command: read as a command about one object of the referent's class
                people += 1
                (referent,) = [a for a in world.actors if a.actor_id == prompt.referent_ids[0]]
                assert reading.command and reading.single, prompt.text
                assert not reading.classes or referent.cls in reading.classes, prompt.text
            elif is_command:
                commands += 1
                assert reading.command and len(reading.texts) == 1, prompt.text
                assert reading.texts[0].lower() in prompt.text.lower(), prompt.text
            else:
                assert reading.texts == (prompt.text,), prompt.text
            if reading.single:
                assert len(prompt.referent_ids) <= 1, prompt.text
    assert seen > 100 and commands > 10 and people > 10


def test_a_command_says_what_it_would_have_needed() -> None:
    from model.tpcnet import answer_note
    from scenes.language.reading import Reading

    bus = read_prompt("follow the bus", VOD)
    assert answer_note(bus, (), VOD) == (
        "No bus here: this model finds cars, pedestrians and cyclists only."
    )
    car = Reading(("the car",), single=True, command=True, classes=("Car",))
    assert answer_note(car, (), VOD) == "No car here to carry out the command."
    assert answer_note(car, ("Car",), VOD) == ""
    assert answer_note(read_prompt("the cars", VOD), (), VOD) == ""
