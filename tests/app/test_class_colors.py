"""Legend colours a person tells apart (issue 48.5): every pair of classes of each class set, and
each class and the referent's green, are at least a CIEDE2000 distance apart with normal vision
and as a reader with deuteranopia or protanopia sees them (Machado et al. 2009's simulation), and
every class colour stands off the viewer's dark background. The distance itself is checked against
Sharma, Wu and Dalal's published CIEDE2000 test pairs."""

from __future__ import annotations

import numpy as np
import pytest

from app.view.color_vision import delta_e2000, min_pair_distance, simulate, srgb_to_lab
from app.view.colors import CLASS_COLORS, GT_COLOR, class_color
from scenes.geometry.classes import PRESETS

MIN_NORMAL = 20.0
"""CIEDE2000 between any two colours of a legend with normal vision (the issue's Car and
TrafficCone oranges were 14.8 apart)."""
MIN_DICHROMAT = 10.0
"""CIEDE2000 between any two colours as a deuteranope or a protanope sees them."""
MIN_BACKGROUND = 30.0
"""CIEDE2000 of every class colour from the viewer's background, in all three visions."""
BACKGROUND = (37, 38, 43)
"""The legend's and the dark viewer's background."""
VISIONS = ("normal", "deuteranopia", "protanopia")


@pytest.mark.parametrize(
    ("lab1", "lab2", "expected"),
    [  # Sharma, Wu, Dalal (2005), table 1: pairs 1, 7, 17, 25 and 13
        ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
        ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
        ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
        ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
        ((50.0, 2.49, -0.001), (50.0, -2.49, 0.0009), 7.1792),
    ],
)
def test_ciede2000_matches_the_published_pairs(lab1, lab2, expected) -> None:
    assert float(delta_e2000(lab1, lab2)) == pytest.approx(expected, abs=1e-4)
    assert float(delta_e2000(lab2, lab1)) == pytest.approx(expected, abs=1e-4)


def test_the_simulations_keep_greys_and_fold_red_onto_green() -> None:
    for vision in VISIONS:
        for grey in (0, 128, 255):
            np.testing.assert_allclose(simulate((grey, grey, grey), vision), [grey] * 3, atol=0.6)
    red, green = srgb_to_lab((255, 0, 0)), srgb_to_lab((0, 160, 0))
    assert float(delta_e2000(red, green)) > 60
    for vision in ("deuteranopia", "protanopia"):  # what a dichromat loses
        seen = [srgb_to_lab(simulate(c, vision)) for c in ((255, 0, 0), (0, 160, 0))]
        assert float(delta_e2000(*seen)) < 25


@pytest.mark.parametrize("preset", sorted(PRESETS))
@pytest.mark.parametrize("vision", VISIONS)
def test_every_pair_of_a_class_set_is_told_apart(preset: str, vision: str) -> None:
    colors = {c.name: c.color for c in PRESETS[preset].classes}
    colors["referent (GT_COLOR)"] = GT_COLOR
    least = MIN_NORMAL if vision == "normal" else MIN_DICHROMAT
    distance, pair = min_pair_distance(colors, vision)
    assert distance >= least, f"{preset}, {vision}: {pair} are only {distance:.1f} apart"


@pytest.mark.parametrize("vision", VISIONS)
def test_every_class_colour_stands_off_the_background(vision: str) -> None:
    background = srgb_to_lab(simulate(BACKGROUND, vision))
    for name, color in CLASS_COLORS.items():
        distance = float(delta_e2000(srgb_to_lab(simulate(color, vision)), background))
        assert distance >= MIN_BACKGROUND, f"{name} {color}: {distance:.1f} from the background"


def test_one_colour_per_class_name_in_every_set() -> None:
    for preset in PRESETS.values():
        for c in preset.classes:
            assert class_color(c.name) == c.color  # the one home: scenes.geometry.classes
