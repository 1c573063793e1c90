"""The Talk2PC sidecar of a sample, ``meta/<id>.json``: :class:`SampleMeta` (prompt type tags,
every actor of the frame with velocities, weather, ego speed, the synthetic world, free-form
extras). It lives outside the Talk2Radar folders, so the official tools never see it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from scenes.geometry.actors import Actor
from scenes.utils.errors import RootError

__all__ = ["SampleMeta"]


@dataclass(frozen=True)
class SampleMeta:
    """The Talk2PC sidecar of a sample (``meta/<id>.json``).

    Attributes:
        tags: Prompt type tags (``class``, ``depth``, ``velocity``, ``motion``, ``position``).
        actors: Every actor of the frame (not only the referred ones), LiDAR frame, with velocities.
        referent_ids: ``actor_id`` of the boxes in ``label_2``, in label order.
        weather: ``clear``, ``rain`` or ``fog``.
        ego_velocity: Ego speed along +x in m/s.
        world_id: Index of the synthetic world (samples of one world share sensor files).
        radar_scans: Number of accumulated radar scans (1, 3 or 5).
        extra: Free-form additions (e.g. annotator, source frame).
    """

    tags: frozenset[str] = frozenset()
    actors: tuple[Actor, ...] = ()
    referent_ids: tuple[int, ...] = ()
    weather: str = "clear"
    ego_velocity: float = 0.0
    world_id: int = -1
    radar_scans: int = 5
    extra: Mapping[str, object] = field(default_factory=dict)

    def to_json(self) -> dict:
        """A JSON-serialisable dict."""
        return {
            "tags": sorted(self.tags),
            "actors": [a.to_json() for a in self.actors],
            "referent_ids": [int(i) for i in self.referent_ids],
            "weather": self.weather,
            "ego_velocity": float(self.ego_velocity),
            "world_id": int(self.world_id),
            "radar_scans": int(self.radar_scans),
            "extra": dict(self.extra),
        }

    @staticmethod
    def from_json(data: dict, source: str = "<meta>") -> SampleMeta:
        """Inverse of :meth:`to_json`; errors name ``source``."""
        if not isinstance(data, dict):
            raise RootError(f"{source}: malformed sidecar: expected a JSON object")
        try:
            return SampleMeta(
                tags=frozenset(data.get("tags", ())),
                actors=tuple(Actor.from_json(a) for a in data.get("actors", ())),
                referent_ids=tuple(int(i) for i in data.get("referent_ids", ())),
                weather=str(data.get("weather", "clear")),
                ego_velocity=float(data.get("ego_velocity", 0.0)),
                world_id=int(data.get("world_id", -1)),
                radar_scans=int(data.get("radar_scans", 5)),
                extra=dict(data.get("extra", {})),
            )
        except (AttributeError, KeyError, TypeError, ValueError, IndexError, OverflowError) as exc:
            raise RootError(f"{source}: malformed sidecar: {exc}") from exc
