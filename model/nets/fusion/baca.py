"""``baca``: Bidirectional Agent Cross Attention (section III-C, eqs. 1-8, fig. 5), the paper's
LiDAR-radar fusion.

BACA, per stage (``L = H * W`` cells, ``l = h * w`` agents, ``n`` heads of width ``d = C / n``):

- eqs. 1-6: ``Q_L, K_L, V_L = (f_l + PE) W_QL, W_KL, W_VL`` and likewise for radar; ``PE`` is the
  fixed 2D sinusoidal encoding of Vaswani et al. [28] (half the channels encode the row, half the
  column; positions normalised to ``[0, 2 pi]`` so that all stages share one scale); the ``W`` are
  linear maps over channels.
- eq. 7: agents ``A_L = Flat(AdaPool(Q_L))`` (adaptive *average* pooling to ``h x w``, default
  12 x 12), ``f_lc = softmax(A_L K_R^T / sqrt(d)) V_R`` (``l x C``: the LiDAR agents gather the
  radar context), ``f_lg = softmax(Q_L A_L^T / sqrt(d)) f_lc`` (``L x C``: broadcast back to every
  LiDAR query).
- eq. 8: the same with the roles swapped gives the radar-driven motion feature ``f_rm``.
- Cost: the two softmax attentions cost ``O(L l C)`` each, the projections ``O(L C^2)``: linear in
  the number of cells. Vanilla cross attention costs ``O(L^2 C)``.

How ``f_lg`` and ``f_rm`` become ``lr`` (the paper does not say; our choice): each passes through
an output projection ``W_O`` (standard for attention) and is added to its own sensor's features as
a residual; the two enriched maps are concatenated and mixed by a 1x1 conv + BatchNorm + ReLU back
to ``C`` channels::

    lr = ReLU(BN(Conv1x1([f_l + f_lg W_OL, f_r + f_rm W_OR])))

The residuals keep each sensor's own evidence when the other sensor is empty or noisy; the 1x1
mixing lets the network weight the two per channel.

The other fusion kinds (:mod:`model.nets.fusion`) keep this merge, so that only the attention
differs; one-direction BACA (:mod:`model.nets.fusion.one_direction`) uses :class:`AgentCrossAttention`.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from model.nets.fusion.baca_cpu import attend_blocked, blocked, folded_direction, softmax_scores
from model.nets.fusion.shared import CrossFusion, Projections, merged, project, project_many


class AgentCrossAttention(Projections):
    """One direction of BACA (eq. 7, or eq. 8 with the sensors swapped).

    Queries come from sensor ``a``, keys and values from sensor ``b``; returns ``f_ag W_O`` as a
    ``(B, C, H, W)`` map (``f_lg`` for a = LiDAR, ``f_rm`` for a = radar).
    """

    def __init__(self, channels: int, agent_size: tuple[int, int], heads: int) -> None:
        super().__init__(channels, heads)
        self.agent_size = (int(agent_size[0]), int(agent_size[1]))

    def forward(self, xa: Tensor, xb: Tensor) -> Tensor:
        """``xa, xb``: ``(B, C, H, W)`` position-encoded maps of the query and key/value sensors."""
        b, c, height, width = xa.shape
        xa, xb = xa.reshape(b, c, -1), xb.reshape(b, c, -1)
        q = project(self.q, xa).view(b, c, height, width)
        fused = self.attend(q, project(self.k, xb), project(self.v, xb))
        return project(self.out, fused).view(b, c, height, width)

    def attend(self, q: Tensor, k: Tensor, v: Tensor) -> Tensor:
        """Eq. 7 on projected maps, channel-major as the maps are: ``Q_a`` ``(B, C, H, W)``,
        ``K_b, V_b`` ``(B, C, L)`` (``L = H * W``) -> ``f_ag`` ``(B, C, L)`` (before ``W_O``).

        No transposing copies: every product reads its operands in place; the ``1 / sqrt(d)``
        scale is applied inside the score products; the agents' scores are ``(B n, l, L)``, the
        queries' ``(B n, L, l)`` (each softmax over its last dim). The same values as
        :func:`model.nets.fusion.shared.attention` on token-major
        tensors, up to float rounding.
        """
        b, c = q.shape[:2]
        n = self.heads
        d = c // n
        scale = d**-0.5
        agents = F.adaptive_avg_pool2d(q, self.agent_size).reshape(b * n, d, -1)  # A_a
        q, k, v = (t.reshape(b * n, d, -1) for t in (q, k, v))
        if b * n == 1 and blocked(q, agents):
            return attend_blocked(q[0], k[0], v[0], agents[0], scale).view(b, c, -1)
        agents_t = agents.transpose(1, 2)  # (B n, l, d)
        gather = softmax_scores(agents_t, k, scale)  # (B n, l, L)
        context = torch.bmm(v, gather.transpose(1, 2))  # f_ac^T: (B n, d, l)
        spread = softmax_scores(q.transpose(1, 2), agents, scale)  # (B n, L, l)
        return torch.bmm(context, spread.transpose(1, 2)).view(b, c, -1)  # f_ag^T


class BidirectionalAgentCrossAttention(CrossFusion):
    """BACA (eqs. 1-8): LiDAR-agent and radar-agent cross attention in both directions.

    Args:
        channels: ``C`` of the stage.
        agent_size: ``(h, w)`` of the context agents.
        heads: Attention heads (``C`` must be divisible by it).
    """

    def __init__(self, channels: int, agent_size: tuple[int, int] = (12, 12), heads: int = 1):
        super().__init__(
            channels,
            AgentCrossAttention(channels, agent_size, heads),
            AgentCrossAttention(channels, agent_size, heads),
        )

    def fuse(self, f_l: Tensor, f_r: Tensor, x_l: Tensor, x_r: Tensor) -> Tensor:
        """:meth:`CrossFusion.fuse` with BACA's own forms of the same arithmetic: at one-head CPU
        inference the projections folded into the agents (:mod:`model.nets.fusion.baca_cpu`),
        else each map's three projections in one product."""
        b, c, height, width = f_l.shape
        lid, rad = self.lidar_dir, self.radar_dir
        if (
            lid.heads == rad.heads == 1
            and b == 1
            and f_l.device.type == "cpu"
            and not torch.is_grad_enabled()
        ):  # one-head BACA at CPU inference: the projections folded into the agents
            both = f_l.new_empty(2, c, height * width)
            for att, xa, xb, fa, out in (
                (lid, x_l, x_r, f_l, both[0]),
                (rad, x_r, x_l, f_r, both[1]),
            ):
                folded_direction(
                    att.q, att.k, att.v, att.out, att.agent_size, xa[0], xb[0].reshape(c, -1),
                    fa[0].reshape(c, -1), out,
                )  # fmt: skip
            out_bias = torch.cat([lid.out.bias, rad.out.bias])
            return merged(self.merge, both.view(1, 2 * c, -1), out_bias).view(b, c, height, width)
        # Each sensor's map feeds its own queries and the other direction's keys and values, so
        # its three projections are one product (rows: Q, K, V).
        from_l = project_many((lid.q, rad.k, rad.v), x_l.reshape(b, c, -1))
        from_r = project_many((rad.q, lid.k, lid.v), x_r.reshape(b, c, -1))
        shape = (b, c, height, width)
        f_lg = lid.attend(from_l[:, :c].view(shape), from_r[:, c : 2 * c], from_r[:, 2 * c :])
        f_rm = rad.attend(from_r[:, :c].view(shape), from_l[:, c : 2 * c], from_l[:, 2 * c :])
        both = torch.cat(
            [
                f_l.reshape(b, c, -1) + project(lid.out, f_lg),
                f_r.reshape(b, c, -1) + project(rad.out, f_rm),
            ],
            dim=1,
        )
        return merged(self.merge, both).view(shape)
