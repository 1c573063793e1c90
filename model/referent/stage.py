"""The referent stage: which of a scene's object candidates does the sentence refer to?

TPCNet's only text path into the BEV is DGGF's per-channel gate from one max-pooled sentence vector
(eqs. 9-11). It cannot compare a cell's depth with "beyond 40 m", a radar velocity with "toward us",
or one object with another ("the nearest", "the two"), and measured so: it picks objects by class.
This stage sits after a text-agnostic C3D-RECHead and decides per candidate (see
:mod:`model.referent.candidates` for what a candidate carries):

1. Candidate tokens: an MLP of the explicit geometry, plus a LiDAR-derived and a radar-derived
   embedding (each the BEV features of that sensor's backbone pooled at the box, with that sensor's
   point evidence), plus the fused BEV features pooled at the box. The LiDAR and radar embeddings
   are scaled by a *prompt-conditioned gate* (sigmoid of a linear map of the mean text token): the
   sentence decides which sensor to trust (the paper's argument for fusion, made per prompt). With
   ``ReferentConfig.text_gate`` the explicit geometry is gated the same way, feature by feature,
   before its MLP (``2 sigmoid``, zero-initialised: 1 until trained), so that a sentence selects
   the few rank or relation columns it asks about instead of the MLP mixing all of them. With
   ``ReferentConfig.numeric_compare`` the geometry is first extended by the comparisons of the
   prompt's numbers with the candidate's depth and speed (:mod:`model.referent.compare`); with
   ``ReferentConfig.subset_ranks`` the candidates' geometry carries the ranks by speed and within
   a side or motion state, and the relations to references picked by speed, side or motion
   (:mod:`model.referent.subsets`, computed once per scene with the candidates).
2. Text tokens: the frozen MiniLM token features concatenated with the value of the number each
   token belongs to (:mod:`model.nets.numerals`), projected to ``dim`` and contextualised by one
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
import torch.nn.functional as F
from torch import Tensor, nn

from model.config import ReferentConfig
from model.nets.numerals import NUMERIC_FEATURES
from model.referent.candidates import LIDAR_EVIDENCE, RADAR_EVIDENCE, geometry_feature_width
from model.referent.compare import COMPARE_FEATURES, compare_features
from model.referent.context import context_width
from model.referent.subsets import subset_width


@dataclass(frozen=True)
class CandidateBatch:
    """Padded candidate descriptions.

    Attributes:
        geometry: ``(N, K, G)`` explicit geometry, ``G`` = :func:`geometry_width` (with the
            context features of :mod:`model.referent.context` after the explicit geometry
            (:func:`model.referent.candidates.geometry_feature_width`) when ``ReferentConfig.context``, then those of
            :mod:`model.referent.subsets` when ``ReferentConfig.subset_ranks``).
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


@dataclass(frozen=True)
class SceneEmbeddings:
    """The text-free part of the candidates' tokens: each candidate's embedding of its fused
    map features and of each sensor's features (``(N, K, dim)``; None for an unused sensor),
    the same for every prompt on a scene (:meth:`ReferentStage.scene_embeddings`)."""

    fused: Tensor
    lidar: Tensor | None
    radar: Tensor | None


def geometry_width(cfg: ReferentConfig, num_classes: int = 3) -> int:
    """Width of :attr:`CandidateBatch.geometry` for a stage of ``cfg`` over ``num_classes``
    classes (3: ``vod``): the explicit geometry, then the context features with ``context``,
    then the subset ranks and picked references (:mod:`model.referent.subsets`) with
    ``subset_ranks``."""
    return (
        geometry_feature_width(num_classes)
        + (context_width(num_classes) if cfg.context else 0)
        + (subset_width(num_classes) if cfg.subset_ranks else 0)
    )


def geometry_input_width(cfg: ReferentConfig, num_classes: int = 3) -> int:
    """Width of the geometry the stage embeds: :func:`geometry_width`, plus the prompt's number
    comparisons (:mod:`model.referent.compare`) with ``numeric_compare``. The embedding's input
    is ordered geometry, context, comparisons, subsets (the order the fields were added in, so
    that a checkpoint without the later ones widens with zero columns at the end)."""
    return geometry_width(cfg, num_classes) + (COMPARE_FEATURES if cfg.numeric_compare else 0)


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
        num_classes: The size of the model's class set (3: ``vod``): the class evidence's
            width (the one-hot and the per-class context and subset blocks).
    """

    def __init__(
        self,
        cfg: ReferentConfig,
        text_dim: int,
        fused_dim: int,
        lidar_dim: int | None,
        radar_dim: int | None,
        num_classes: int = 3,
    ) -> None:
        super().__init__()
        d = cfg.dim
        self.cfg = cfg
        self.num_classes = num_classes
        width = geometry_input_width(cfg, num_classes)
        self.geometry = _mlp(width, d)
        self.fused = _mlp(fused_dim, d)
        self.lidar = _mlp(lidar_dim + LIDAR_EVIDENCE, d) if lidar_dim is not None else None
        self.radar = _mlp(radar_dim + RADAR_EVIDENCE, d) if radar_dim is not None else None
        self.sensor_gate = nn.Linear(d, 2 * d)
        self.geometry_gate = nn.Linear(d, width) if cfg.text_gate else None
        if self.geometry_gate is not None:
            nn.init.zeros_(self.geometry_gate.weight)
            nn.init.zeros_(self.geometry_gate.bias)
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

    def encode_text(self, tokens: Tensor, numbers: Tensor, padding: Tensor) -> Tensor:
        """``(N, T, D_text)`` tokens + ``(N, T, NUMERIC_FEATURES)`` numbers -> ``(N, T, dim)``."""
        x = self.text_in(torch.cat([tokens, numbers.to(tokens.dtype)], dim=-1))
        return self.text_context(x, src_key_padding_mask=padding)

    def scene_embeddings(self, cands: CandidateBatch) -> SceneEmbeddings:
        """The embeddings of :class:`SceneEmbeddings` for ``cands`` (no text involved)."""
        return SceneEmbeddings(
            self.fused(cands.fused),
            None if self.lidar is None or cands.lidar is None else self.lidar(cands.lidar),
            None if self.radar is None or cands.radar is None else self.radar(cands.radar),
        )

    def candidate_tokens(
        self,
        cands: CandidateBatch,
        text: Tensor,
        numbers: Tensor,
        text_padding: Tensor,
        embedded: SceneEmbeddings | None = None,
    ) -> Tensor:
        """The candidates' tokens ``(N, K, dim)``: the geometry's (with ``numeric_compare``
        extended by the comparisons with the prompt's ``numbers`` ``(N, T, NUMERIC_FEATURES)``;
        with ``text_gate`` gated by the prompt) and the fused map's embeddings, plus each
        sensor's embedding scaled by the prompt's gate for that sensor ``(N, 2, dim)`` in
        ``(0, 1)``, normalised. ``embedded``: :meth:`scene_embeddings` of ``cands`` when already
        computed (inference on a scene asked before)."""
        keep = (~text_padding).to(text.dtype)[..., None]
        mean = (text * keep).sum(1) / keep.sum(1).clamp(min=1.0)  # (N, dim)
        gate = torch.sigmoid(self.sensor_gate(mean)).view(-1, 2, self.cfg.dim)
        geometry = cands.geometry
        if self.cfg.numeric_compare:
            compared = compare_features(geometry, cands.radar, numbers, text_padding)
            if self.cfg.subset_ranks:  # geometry_input_width's order: the subsets come last
                split = geometry.shape[-1] - subset_width(self.num_classes)
                parts = [geometry[..., :split], compared, geometry[..., split:]]
            else:
                parts = [geometry, compared]
            geometry = torch.cat(parts, dim=-1)
        if self.geometry_gate is not None:
            geometry = geometry * (2.0 * torch.sigmoid(self.geometry_gate(mean)))[:, None, :]
        if embedded is None:
            embedded = self.scene_embeddings(cands)
        x = self.geometry(geometry) + embedded.fused
        if embedded.lidar is not None:
            x = x + gate[:, None, 0] * embedded.lidar
        if embedded.radar is not None:
            x = x + gate[:, None, 1] * embedded.radar
        return self.cand_norm(x)

    def forward(
        self,
        cands: CandidateBatch,
        tokens: Tensor,
        numbers: Tensor | None,
        text_padding: Tensor,
        embedded: SceneEmbeddings | None = None,
    ) -> Tensor:
        """Referent logits ``(N, K)`` (padding positions hold -inf-like values, -1e4).

        At inference (eval mode, no gradient) the same computation runs written out
        (:meth:`_infer`): equal to float rounding, in a fraction of the time; it takes the
        scene's :meth:`scene_embeddings` as ``embedded`` where the caller kept them (they are
        computed otherwise, and always in training)."""
        if numbers is None:  # features made without numerals (TextFeatures.numbers is optional)
            numbers = tokens.new_zeros((*tokens.shape[:2], NUMERIC_FEATURES))
        if not self.training and not torch.is_grad_enabled():
            return self._infer(cands, tokens, numbers, text_padding, embedded)
        text = self.encode_text(tokens, numbers, text_padding)
        x = self.candidate_tokens(cands, text, numbers, text_padding)
        for block in self.blocks:
            x = block(
                x,
                text,
                tgt_key_padding_mask=cands.padding,
                memory_key_padding_mask=text_padding,
            )
        logits = self.out(self.out_norm(x))[..., 0]
        return logits.masked_fill(cands.padding, -1e4)

    # ---------------------------------------------------------------- inference, written out

    def _infer(
        self,
        cands: CandidateBatch,
        tokens: Tensor,
        numbers: Tensor,
        text_padding: Tensor,
        embedded: SceneEmbeddings | None,
    ) -> Tensor:
        """:meth:`forward` without gradients: the layers' arithmetic called directly
        (``F.linear``, fused ``scaled_dot_product_attention``, ``F.layer_norm``) instead of
        through ``nn.TransformerEncoderLayer`` / ``nn.TransformerDecoderLayer`` and their
        fast-path checks; masks are dropped where nothing is padded."""
        text_mask = _attend(text_padding)
        ctx = self.text_context
        text = self.text_in(torch.cat([tokens, numbers.to(tokens.dtype)], dim=-1))
        text = text + _attention(ctx.self_attn, ctx.norm1(text), None, text_mask)
        text = text + _feed_forward(ctx, ctx.norm2(text))
        x = self.candidate_tokens(cands, text, numbers, text_padding, embedded)
        cand_mask = _attend(cands.padding)
        for block in self.blocks:
            x = x + _attention(block.self_attn, block.norm1(x), None, cand_mask)
            x = x + _attention(block.multihead_attn, block.norm2(x), text, text_mask)
            x = x + _feed_forward(block, block.norm3(x))
        logits = self.out(self.out_norm(x))[..., 0]
        return logits.masked_fill(cands.padding, -1e4)


def _attend(padding: Tensor) -> Tensor | None:
    """``scaled_dot_product_attention``'s mask ``(N, 1, 1, L)`` (True: attend) of a key padding
    mask ``(N, L)`` (True: padding), or None where nothing is padded."""
    if not bool(padding.any()):
        return None
    return ~padding[:, None, None, :]


def _attention(mha: nn.MultiheadAttention, x: Tensor, memory: Tensor | None, mask: Tensor | None):
    """``mha(x, m, m, key_padding_mask=...)[0]`` of a batch-first ``nn.MultiheadAttention``
    (``m`` = ``memory``, or ``x`` for self-attention; no dropout), written out."""
    n, lq, d = x.shape
    heads = mha.num_heads
    w, b = mha.in_proj_weight, mha.in_proj_bias
    if memory is None:
        q, k, v = F.linear(x, w, b).view(n, lq, 3, heads, d // heads).permute(2, 0, 3, 1, 4)
    else:
        q = F.linear(x, w[:d], b[:d]).view(n, lq, heads, d // heads).transpose(1, 2)
        lk = memory.shape[1]
        kv = F.linear(memory, w[d:], b[d:]).view(n, lk, 2, heads, d // heads)
        k, v = kv.permute(2, 0, 3, 1, 4)
    a = F.scaled_dot_product_attention(q, k, v, attn_mask=mask)
    return mha.out_proj(a.transpose(1, 2).reshape(n, lq, d))


def _feed_forward(layer: nn.TransformerEncoderLayer | nn.TransformerDecoderLayer, x: Tensor):
    """The layer's feed-forward block (no dropout)."""
    return layer.linear2(layer.activation(layer.linear1(x)))


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


__all__ = [
    "CandidateBatch",
    "ReferentStage",
    "SceneEmbeddings",
    "geometry_input_width",
    "geometry_width",
    "referent_loss",
]
