"""``lidar_query`` and ``radar_query``: one direction of BACA only (table VIII's ``L_Q + R_KV`` and
``R_Q + L_KV``); the other sensor enters BACA's merge unchanged. One class for the two kinds: they
differ only in which sensor asks."""

from __future__ import annotations

from model.nets.fusion.baca import AgentCrossAttention
from model.nets.fusion.shared import CrossFusion


class UnidirectionalAgentCrossAttention(CrossFusion):
    """One direction of BACA only: ``query="lidar"`` is ``L_Q + R_KV``, ``"radar"`` is ``R_Q + L_KV``."""

    def __init__(
        self,
        channels: int,
        query: str,
        agent_size: tuple[int, int] = (12, 12),
        heads: int = 1,
    ) -> None:
        if query not in ("lidar", "radar"):
            raise ValueError(f"query must be 'lidar' or 'radar', got {query!r}")
        direction = AgentCrossAttention(channels, agent_size, heads)
        super().__init__(
            channels,
            direction if query == "lidar" else None,
            direction if query == "radar" else None,
        )
