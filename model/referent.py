"""The referent stage: which of a scene's object candidates does the sentence refer to?

TPCNet's only text path into the BEV is DGGF's per-channel gate from one max-pooled sentence vector
(eqs. 9-11). It cannot compare a cell's depth with "beyond 40 m", a radar velocity with "toward us",
or one object with another ("the nearest", "the two"), and measured so: it picks objects by class.
This stage sits after a text-agnostic C3D-RECHead and decides per candidate (see
:mod:`model.candidates` for what a candidate carries):

1. Candidate tokens: an MLP of the explicit geometry, plus a LiDAR-derived and a radar-derived
   embedding (each the BEV features of that sensor's backbone pooled at the box, with that sensor's
   point evidence), plus the fused BEV features pooled at the box. The LiDAR and radar embeddings
   are scaled by a *prompt-conditioned gate* (sigmoid of a linear map of the mean text token): the
   sentence decides which sensor to trust (the paper's argument for fusion, made per prompt).
2. Text tokens: the frozen MiniLM token features concatenated with the value of the number each
   token belongs to (:mod:`model.numerals`), projected to ``dim`` and contextualised by one
   self-attention layer.
3. ``layers`` decoder blocks over the candidates: self-attention among candidates (superlatives and
   counts need comparisons), cross-attention to the text tokens, feed-forward (pre-norm).
4. One referent logit per candidate.

Shapes: ``N`` (prompt, scene) pairs, ``K`` candidates (padded, ``cand_padding`` True at padding),
``T`` tokens. Every candidate row must have at least one real candidate.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from model.candidates import GEOMETRY_FEATURES, LIDAR_EVIDENCE, RADAR_EVIDENCE
from model.config import ReferentConfig
from model.numerals import NUMERIC_FEATURES


@dataclass(frozen=True)
class CandidateBatch:
    """Padded candidate descriptions.

    Attributes:
        geometry: ``(N, K, GEOMETRY_FEATURES)`` explicit geometry.
        fused: ``(N, K, C_f)`` fused BEV features pooled at the box (centre and anchor).
        lidar: ``(N, K, C_l + LIDAR_EVIDENCE)`` or None for a radar-only model.
        radar: ``(N, K, C_r + RADAR_EVIDENCE)`` or None for a LiDAR-only model.
        padding: ``(N, K)`` bool, True at padding.
    """

    geometry: Tensor
    fused: Tensor
    lidar: Tensor | None
    radar: Tensor | None
    padding: Tensor

    def index(self, rows: Tensor) -> CandidateBatch:
        """The batch with rows ``rows`` (``(N',)`` long), e.g. one row per prompt of a scene."""

        def pick(t: Tensor | None) -> Tensor | None:
            return None if t is None else t.index_select(0, rows)

        return CandidateBatch(
            pick(self.geometry), pick(self.fused), pick(self.lidar), pick(self.radar),
            pick(self.padding),
        )  # fmt: skip


def _mlp(inp: int, dim: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inp, dim), nn.GELU(), nn.Linear(dim, dim))


class ReferentStage(nn.Module):
    """Referent logits for candidates given a prompt's tokens (module docstring).

    Args:
        cfg: Sizes.
        text_dim: Width of the text encoder's token features.
        fused_dim: Width of :attr:`CandidateBatch.fused`.
        lidar_dim: BEV channels pooled from the LiDAR branch (None: no LiDAR).
        radar_dim: BEV channels pooled from the radar branch (None: no radar).
    """

    def __init__(
        self,
        cfg: ReferentConfig,
        text_dim: int,
        fused_dim: int,
        lidar_dim: int | None,
        radar_dim: int | None,
    ) -> None:
        super().__init__()
        d = cfg.dim
        self.cfg = cfg
        self.geometry = _mlp(GEOMETRY_FEATURES, d)
        self.fused = _mlp(fused_dim, d)
        self.lidar = _mlp(lidar_dim + LIDAR_EVIDENCE, d) if lidar_dim is not None else None
        self.radar = _mlp(radar_dim + RADAR_EVIDENCE, d) if radar_dim is not None else None
        self.sensor_gate = nn.Linear(d, 2 * d)
        self.cand_norm = nn.LayerNorm(d)
        self.text_in = nn.Sequential(nn.Linear(text_dim + NUMERIC_FEATURES, d), nn.LayerNorm(d))
        self.text_context = nn.TransformerEncoderLayer(
            d, cfg.heads, cfg.ffn_ratio * d, cfg.dropout, batch_first=True, norm_first=True
        )
        self.blocks = nn.ModuleList(
            nn.TransformerDecoderLayer(
                d, cfg.heads, cfg.ffn_ratio * d, cfg.dropout, batch_first=True, norm_first=True
            )
            for _ in range(cfg.layers)
        )
        self.out_norm = nn.LayerNorm(d)
        self.out = nn.Linear(d, 1)

    def encode_text(self, tokens: Tensor, numbers: Tensor | None, padding: Tensor) -> Tensor:
        """``(N, T, D_text)`` tokens + ``(N, T, NUMERIC_FEATURES)`` numbers -> ``(N, T, dim)``."""
        if numbers is None:
            numbers = tokens.new_zeros((*tokens.shape[:2], NUMERIC_FEATURES))
        x = self.text_in(torch.cat([tokens, numbers.to(tokens.dtype)], dim=-1))
        return self.text_context(x, src_key_padding_mask=padding)

    def gates(self, text: Tensor, padding: Tensor) -> Tensor:
        """Prompt-conditioned sensor gates ``(N, 2, dim)`` in ``(0, 1)``: LiDAR, radar."""
        keep = (~padding).to(text.dtype)[..., None]
        mean = (text * keep).sum(1) / keep.sum(1).clamp(min=1.0)
        return torch.sigmoid(self.sensor_gate(mean)).view(-1, 2, self.cfg.dim)

    def forward(
        self,
        cands: CandidateBatch,
        tokens: Tensor,
        numbers: Tensor | None,
        text_padding: Tensor,
    ) -> Tensor:
        """Referent logits ``(N, K)`` (padding positions hold -inf-like values, -1e4)."""
        text = self.encode_text(tokens, numbers, text_padding)
        gate = self.gates(text, text_padding)
        x = self.geometry(cands.geometry) + self.fused(cands.fused)
        if self.lidar is not None and cands.lidar is not None:
            x = x + gate[:, None, 0] * self.lidar(cands.lidar)
        if self.radar is not None and cands.radar is not None:
            x = x + gate[:, None, 1] * self.radar(cands.radar)
        x = self.cand_norm(x)
        for block in self.blocks:
            x = block(
                x,
                text,
                tgt_key_padding_mask=cands.padding,
                memory_key_padding_mask=text_padding,
            )
        logits = self.out(self.out_norm(x))[..., 0]
        return logits.masked_fill(cands.padding, -1e4)


def referent_loss(logits: Tensor, targets: Tensor, padding: Tensor) -> tuple[Tensor, Tensor]:
    """Binary cross-entropy per candidate + a listwise term.

    Args:
        logits: ``(N, K)`` from :class:`ReferentStage`.
        targets: ``(N, K)`` float, 1 for a referent.
        padding: ``(N, K)`` bool.

    Returns:
        ``(bce, listwise)``: the mean BCE over real candidates, and the cross-entropy of the softmax
        over each row's candidates against the uniform distribution over its referents (rows
        without a referent are skipped); both scalars.
    """
    valid = ~padding
    bce = nn.functional.binary_cross_entropy_with_logits(logits, targets, reduction="none")
    bce = (bce * valid).sum() / valid.sum().clamp(min=1)
    pos = targets * valid
    has = pos.sum(1) > 0
    if not bool(has.any()):
        return bce, logits.new_zeros(())
    logp = torch.log_softmax(logits[has], dim=1)
    dist = pos[has] / pos[has].sum(1, keepdim=True)
    listwise = -(dist * logp).sum(1).mean()
    return bce, listwise


__all__ = ["CandidateBatch", "ReferentStage", "referent_loss"]
