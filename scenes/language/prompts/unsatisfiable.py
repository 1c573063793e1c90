"""The unsatisfiable family's forms: predicates that fit nobody in the scene.

Four forms (:data:`UNSATISFIABLE_FORMS`, with their shares): an imagined actor's attributes that
happen to fit nobody here, a distance or speed beyond any actor, a place behind us, and a
contradiction (standing still yet approaching, or doing 20 km/h). Each returns a predicate or
None; :func:`scenes.language.prompts.extended.generate_extended` keeps it only when it resolves crisply
to nothing.
"""

from __future__ import annotations

from collections.abc import Callable

from scenes.geometry.classes import class_set
from scenes.language.prompts.atoms import (
    Atom,
    Heading,
    HeadingIs,
    MotionState,
    SpeedAbove,
    SpeedUnit,
)
from scenes.language.prompts.families import Behind, Direction, Travel
from scenes.language.prompts.predicate import Predicate
from scenes.language.prompts.sampling import depth_atom, speed_atom
from scenes.language.prompts.scene_draw import DrawScene, fake_actor, sampled


def _unsat_sampled(sc: DrawScene) -> Predicate | None:
    """A predicate of an imagined actor (:func:`_fake`) that happens to fit nobody here."""
    return sampled(sc, fake_actor(sc), 2, extreme=True)


def _unsat_absurd(sc: DrawScene) -> Predicate | None:
    """A distance or speed beyond any actor: "the car 250 m ahead", "a pedestrian doing 60 km/h"."""
    rng = sc.rng
    fast = rng.random() < 0.5
    f = fake_actor(sc, far=not fast, fast=fast)
    atom = speed_atom(f, rng) if fast else depth_atom(f, rng)
    if atom is None:
        return None
    atoms: list[Atom] = [atom]
    other = sampled(sc, f, 1, extreme=False)
    if (
        other is not None
        and other.atoms
        and other.atoms[0].family != atom.family
        and rng.random() < 0.4
    ):
        atoms.append(other.atoms[0])
    return Predicate(f.cls if rng.random() < 0.9 else None, tuple(atoms))


def _unsat_behind(sc: DrawScene) -> Predicate | None:
    """Something behind us (:class:`~scenes.language.prompts.families.Behind`), maybe with its motion."""
    f = fake_actor(sc)
    other = sampled(sc, f, 1, extreme=False)
    atoms: list[Atom] = [Behind()]
    if other is not None and other.atoms and other.atoms[0].family in ("motion", "heading"):
        atoms.append(other.atoms[0])
    return Predicate(f.cls if sc.rng.random() < 0.9 else None, tuple(atoms))


def _unsat_contradiction(sc: DrawScene) -> Predicate | None:
    """Standing still and moving at once: "the parked car approaching us", "a stationary
    cyclist going 20 km/h"."""
    rng = sc.rng
    kmh = bool(rng.random() < 0.5)
    speed = (
        SpeedAbove(float(rng.choice((10, 15, 20, 25, 30, 40))), SpeedUnit.KMH)
        if kmh
        else SpeedAbove(float(rng.integers(2, 10)), SpeedUnit.MPS)
    )
    moving: list[Atom] = [
        HeadingIs(Heading.APPROACHING),
        HeadingIs(Heading.AWAY),
        HeadingIs(Heading.CROSSING),
        Travel(Direction.SAME),
        Travel(Direction.OPPOSITE),
        speed,
    ]
    atom = moving[int(rng.integers(len(moving)))]
    names = class_set(sc.cfg.classes).names
    cls = names[int(rng.integers(len(names)))]
    return Predicate(cls, (MotionState(False), atom))


UNSATISFIABLE_FORMS: tuple[tuple[Callable[[DrawScene], Predicate | None], float], ...] = (
    (_unsat_sampled, 0.4),
    (_unsat_absurd, 0.25),
    (_unsat_behind, 0.15),
    (_unsat_contradiction, 0.2),
)
"""The unsatisfiable family's forms and their shares."""
