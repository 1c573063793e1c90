"""Pillar voxelisation and pillar feature nets for LiDAR and radar (section III-B, PointPillars).

Each sensor's points (LiDAR frame) are binned into vertical pillars on the BEV grid of
:mod:`model.core.grid`; pillar ``(iy, ix)`` lands on the canvas at ``canvas[:, iy, ix]`` (row = y index,
column = x index). Per point the PFN sees

- the raw features times a fixed per-feature scale (``PillarConfig.lidar_scale``/``radar_scale``;
  LiDAR intensity 0..255 becomes 0..1, radar RCS and velocities are brought near unit range),
- ``(x, y, z)`` minus the mean of the pillar's kept points (3),
- ``(x, y, z)`` minus the pillar's geometric centre (3); the centre's z is the middle of
  ``[z_min, z_max)``,

i.e. 4 + 6 = 10 channels for LiDAR and 7 + 6 = 13 for radar, as PointPillars and Talk2Radar's
``Radar7PillarFeatureNet``. One PFN layer follows: Linear (no bias) + BatchNorm1d + ReLU, then a
max over the points of each pillar.

Choices where PointPillars' reference is silent or odd:

- Voxelisation is done with tensor ops (one stable ``argsort`` of the flat cell keys, then
  ``unique_consecutive`` for the pillars and the within-pillar rank; ``index_add``/
  ``scatter_reduce`` for the mean and the max), no Python loop over points, no compiled extension
  to build. One cloud at inference (the app's ``encode_scene``) takes
  :mod:`model.nets.pillar_kernel` instead: the same arithmetic as one loop over the points,
  compiled by numba on first use (issue 20: about a third of the time on a full LiDAR spin).
- A pillar keeps its first ``max_points`` points in input order (32 LiDAR, 10 radar as the paper);
  the pillar mean is over the kept points. There is no cap on the number of pillars.
- The max runs over the real points only: PointPillars' zero-padded slots (which become
  ``BN(0)`` after the PFN and take part in its max) do not exist here, and BatchNorm statistics
  are over real points only.
- Points outside the grid's x/y range or outside ``[z_min, z_max)`` are dropped; an empty cloud
  gives an all-zero canvas.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.config import PillarConfig
from model.core.grid import BevGrid
from model.nets.folding import batchnorm_affine
from model.nets.pillar_kernel import PillarWeights, encode_cloud


@dataclass(frozen=True)
class Pillars:
    """The kept points of a batch grouped into pillars.

    Attributes:
        points: ``(N, F)`` float32 kept points (raw features, LiDAR frame), grouped by pillar.
        pillar_of_point: ``(N,)`` int64 index into the pillar arrays below.
        keys: ``(P,)`` int64 flat canvas index ``(b * H + iy) * W + ix`` of each pillar, ascending.
        counts: ``(P,)`` int64 kept points per pillar (``1..max_points``).
        batch_size: ``B``.
    """

    points: Tensor
    pillar_of_point: Tensor
    keys: Tensor
    counts: Tensor
    batch_size: int


def voxelize(
    clouds: Sequence[Tensor], grid: BevGrid, z_min: float, z_max: float, max_points: int
) -> Pillars:
    """Group a batch of point clouds into pillars.

    Args:
        clouds: ``B`` tensors ``(N_b, F)`` (x, y, z first), LiDAR frame, finite.
        grid: The pillar grid.
        z_min, z_max: Vertical range kept, metres.
        max_points: Points kept per pillar (the first ones in input order).

    Returns:
        :class:`Pillars`; empty arrays when no point is in range.
    """
    if len(clouds) == 0:
        raise ValueError("voxelize needs at least one point cloud (batch size 0)")
    num_features = clouds[0].shape[1]
    device = clouds[0].device
    batch = None
    if len(clouds) == 1 and device.type == "cpu":
        return _voxelize_one_cpu(
            clouds[0].reshape(-1, num_features), grid, z_min, z_max, max_points
        )
    if len(clouds) == 1:  # the app's case: no copy of the cloud, no batch index
        points = clouds[0].reshape(-1, num_features)
    else:
        points = torch.cat([c.reshape(-1, num_features) for c in clouds], dim=0)
        batch = torch.repeat_interleave(
            torch.arange(len(clouds), device=device),
            torch.tensor([c.shape[0] for c in clouds], device=device),
        )
    ny, nx = grid.shape
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    inside = (
        (x >= grid.x_min)
        & (x < grid.x_max)
        & (y >= grid.y_min)
        & (y < grid.y_max)
        & (z >= z_min)
        & (z < z_max)
    )
    # One index of the points in range (cheaper than masking four tensors), gathered once at the
    # end; cells are computed for those points only, and checked (rounding can put a point just
    # below x_max into column nx).
    selected = torch.nonzero(inside).squeeze(1)
    col = torch.floor((x.index_select(0, selected) - grid.x_min) / grid.cell).long()
    row = torch.floor((y.index_select(0, selected) - grid.y_min) / grid.cell).long()
    in_grid = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
    if not bool(in_grid.all()):
        keep = torch.nonzero(in_grid).squeeze(1)
        selected, col, row = selected[keep], col[keep], row[keep]
    keys_of_point = row * nx + col
    if batch is not None:
        keys_of_point = keys_of_point + batch.index_select(0, selected) * (ny * nx)
    # One stable sort groups the points by pillar and keeps their input order within a pillar.
    order = _stable_order(keys_of_point, len(clouds) * ny * nx)
    if device.type == "cpu" and order.numel():
        return _group_cpu(points, selected, keys_of_point, order, max_points, len(clouds))
    keys, pillar_sorted, counts = torch.unique_consecutive(
        keys_of_point[order], return_inverse=True, return_counts=True
    )
    starts = torch.cumsum(counts, 0) - counts
    rank = torch.arange(order.numel(), device=device) - starts[pillar_sorted]
    kept = rank < max_points
    return Pillars(
        points=points.index_select(0, selected[order[kept]]),
        pillar_of_point=pillar_sorted[kept],
        keys=keys,
        counts=counts.clamp(max=max_points),
        batch_size=len(clouds),
    )


def _voxelize_one_cpu(
    points: Tensor, grid: BevGrid, z_min: float, z_max: float, max_points: int
) -> Pillars:
    """:func:`voxelize` of one CPU cloud ``(N, F)``, in NumPy (its in-place masks and gathers
    cost a fraction of the tensor form's on ~190k points): the same arrays, the same values (the
    range tests and the cell arithmetic in float32, as the tensor form does them). The three
    coordinate columns are copied out once, so that the six range tests and the gathers after
    them run over contiguous arrays (strided, each of them costs about twice as much)."""
    pts = points.numpy()
    ny, nx = grid.shape
    f32 = np.float32
    x, y, z = pts[:, :3].T.copy()
    inside = x >= f32(grid.x_min)
    inside &= x < f32(grid.x_max)
    inside &= y >= f32(grid.y_min)
    inside &= y < f32(grid.y_max)
    inside &= z >= f32(z_min)
    inside &= z < f32(z_max)
    selected = np.flatnonzero(inside)
    col = np.floor((x[selected] - f32(grid.x_min)) / f32(grid.cell)).astype(np.int64)
    row = np.floor((y[selected] - f32(grid.y_min)) / f32(grid.cell)).astype(np.int64)
    in_grid = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
    if not in_grid.all():
        selected, col, row = selected[in_grid], col[in_grid], row[in_grid]
    keys_of_point = row * nx + col
    if not len(selected):
        empty = torch.zeros(0, dtype=torch.long)
        return Pillars(points[:0], empty, empty, empty, 1)
    order = _stable_order(torch.from_numpy(keys_of_point), ny * nx)
    return _group_cpu(
        points, torch.from_numpy(selected), torch.from_numpy(keys_of_point), order, max_points, 1
    )


def _group_cpu(
    points: Tensor,
    selected: Tensor,
    keys_of_point: Tensor,
    order: Tensor,
    max_points: int,
    batch_size: int,
) -> Pillars:
    """The grouping of :func:`voxelize` in NumPy on the CPU (the same arrays as the tensor
    form, in about a third of its time: its boolean masks and gathers are cheaper there)."""
    o = order.numpy()
    sorted_keys = keys_of_point.numpy()[o]
    new = np.empty(len(sorted_keys), dtype=bool)
    new[0] = True
    np.not_equal(sorted_keys[1:], sorted_keys[:-1], out=new[1:])
    first = np.flatnonzero(new)
    pillar = np.cumsum(new) - 1
    kept = np.arange(len(sorted_keys)) - first[pillar] < max_points
    counts = np.minimum(np.diff(np.append(first, len(sorted_keys))), max_points)
    return Pillars(
        points=torch.from_numpy(np.take(points.numpy(), selected.numpy()[o[kept]], axis=0)),
        pillar_of_point=torch.from_numpy(pillar[kept]),
        keys=torch.from_numpy(sorted_keys[first]),
        counts=torch.from_numpy(counts),
        batch_size=batch_size,
    )


_RADIX_KEYS = 1 << 16
"""Key spaces up to this size are sorted as uint16 (NumPy's stable sort of 16-bit integers is a
radix sort, about 5x faster than ``torch.argsort(stable=True)`` on the 130,000 points of a
forward half-scan; one 160 x 160 grid has 25,600 keys)."""


def _stable_order(keys: Tensor, key_space: int) -> Tensor:
    """``(N,)`` int64 permutation that sorts ``keys (N,)`` (values in ``[0, key_space)``) stably:
    the same permutation either way, by a radix sort on the CPU when the keys fit 16 bits."""
    if keys.device.type == "cpu" and key_space <= _RADIX_KEYS:
        order = np.argsort(keys.numpy().astype(np.uint16), kind="stable")
        return torch.from_numpy(order.astype(np.int64))
    return torch.argsort(keys, stable=True)


def _batch_norm_points(bn: nn.BatchNorm1d, x: Tensor) -> Tensor:
    """BatchNorm1d over points that tolerates fewer than two points in training mode."""
    if bn.training and x.shape[0] < 2:
        return F.batch_norm(
            x, bn.running_mean, bn.running_var, bn.weight, bn.bias, False, 0.0, bn.eps
        )
    return bn(x)


class PillarEncoder(nn.Module):
    """Pillar feature net + scatter for one sensor.

    Args:
        cfg: Pillar configuration (grid, z range, PFN width).
        num_features: Raw features per point (4 LiDAR, 7 radar).
        max_points: Points kept per pillar.
        scale: Fixed per-feature scale of the raw features.
    """

    def __init__(
        self, cfg: PillarConfig, num_features: int, max_points: int, scale: Sequence[float]
    ) -> None:
        super().__init__()
        if len(scale) != num_features:
            raise ValueError(f"PillarEncoder: {len(scale)} scales for {num_features} features")
        self.grid = cfg.grid
        self.z_min, self.z_max = cfg.z_min, cfg.z_max
        self.num_features = num_features
        self.max_points = max_points
        self.out_channels = cfg.channels
        self.register_buffer(
            "scale", torch.tensor(list(scale), dtype=torch.float32), persistent=False
        )
        self.linear = nn.Linear(num_features + 6, cfg.channels, bias=False)
        self.norm = nn.BatchNorm1d(cfg.channels, eps=1e-3, momentum=0.1)

    def point_features(self, pillars: Pillars) -> Tensor:
        """``(N, F + 6)`` PFN input: scaled raw features, offsets to pillar mean and centre."""
        pts = pillars.points
        xyz = pts[:, :3]
        # Each pillar's mean and centre once, then gathered (the same values per point).
        mean, centre = self._pillar_points(pillars)
        per_pillar = torch.cat([mean, centre], dim=1).index_select(0, pillars.pillar_of_point)
        f = self.num_features
        out = torch.empty(pts.shape[0], f + 6, device=pts.device, dtype=pts.dtype)
        torch.mul(pts, self.scale, out=out[:, :f])
        torch.sub(xyz, per_pillar[:, :3], out=out[:, f : f + 3])
        torch.sub(xyz, per_pillar[:, 3:], out=out[:, f + 3 :])
        return out

    def _pooled(self, pillars: Pillars) -> Tensor:
        """``(P, C)``: per pillar the max over its points of ``ReLU(BN(Linear(features)))``.

        With running statistics (eval mode) BatchNorm is ``a * h + b`` per channel, and it and
        ReLU are monotone: the max of ``ReLU(BN(h))`` over a pillar is ``ReLU(BN(max h))`` where
        ``a >= 0`` and ``ReLU(BN(min h))`` where ``a < 0`` (rounding is monotone too, so the
        values are the same bit for bit). So the pillars are pooled first, from the linear map
        with the ``a < 0`` channels' weights negated (``max(-h) = -min(h)`` exactly), and
        normalised after: the per-point BatchNorm and ReLU are not computed. In training the
        statistics are the points', and every point is normalised.
        """
        channels = self.out_channels
        index = pillars.pillar_of_point.unsqueeze(1).expand(-1, channels)
        if self.norm.training:
            h = torch.relu(_batch_norm_points(self.norm, self.linear(self.point_features(pillars))))
            pooled = torch.zeros(pillars.keys.numel(), channels, device=h.device, dtype=h.dtype)
            return pooled.scatter_reduce(0, index, h, reduce="amax", include_self=False)
        return self._pooled_eval(pillars, index)

    def _pooled_eval(self, pillars: Pillars, index: Tensor) -> Tensor:
        """:meth:`_pooled` with running statistics, the linear map split by what varies within
        a pillar. The PFN input is ``[s * p, xyz - mean, xyz - centre]`` (``p`` the raw point,
        ``xyz`` its first three features), so ``W x = M p - (W_mean mean + W_centre centre)``
        with ``M = W_raw * s`` plus ``W_mean + W_centre`` on the xyz columns: the second term is
        one value per pillar, so the max over a pillar's points is taken of ``M p`` (an
        ``F``-wide product of the raw points, no per-point features built) and the pillar term
        subtracted after. The same values up to float rounding."""
        pts = pillars.points
        sign, raw, per_pillar = self._factorised(pts.dtype)
        h = F.linear(pts, raw)  # (N, C)
        pooled = torch.zeros(
            pillars.keys.numel(), self.out_channels, dtype=h.dtype, device=h.device
        )
        pooled = pooled.scatter_reduce(0, index, h, reduce="amax", include_self=False)
        mean, centre = self._pillar_points(pillars)
        # Out of place: autograd needs the amax's output (batch-norm layers held in eval mode
        # while the PFN learns, ``python -m model.adapt --norm-statistics keep``).
        pooled = pooled - torch.cat([mean, centre], dim=1) @ per_pillar.t()
        return torch.relu(self.norm(pooled * sign))

    def _factorised(self, dtype: torch.dtype) -> tuple[Tensor, Tensor, Tensor]:
        """The PFN's linear map split as :meth:`_pooled_eval` says: each channel's sign ``(C,)``
        (+1 where the BatchNorm's gamma is >= 0, else -1: ``max(-h) = -min(h)``), the map of a
        raw point ``M`` ``(C, F)`` and the per-pillar term's weights ``[W_mean, W_centre]``
        ``(C, 6)``, both sign-flipped."""
        f = self.num_features
        sign = torch.where(self.norm.weight >= 0, 1.0, -1.0).to(dtype)
        weight = self.linear.weight * sign[:, None]  # (C, F + 6)
        raw = weight[:, :f] * self.scale
        raw[:, :3] += weight[:, f : f + 3] + weight[:, f + 3 :]
        return sign, raw, weight[:, f:]

    def kernel_weights(self) -> PillarWeights:
        """The eval-mode PFN as :func:`model.nets.pillar_kernel.encode_cloud` reads it: the
        factorisation of :meth:`_pooled_eval` (:meth:`_factorised`) and the BatchNorm's running
        statistics as a scale and a shift per channel."""
        with torch.no_grad():
            sign, raw, per_pillar = self._factorised(torch.float32)
            scale, shift = batchnorm_affine(self.norm)

        def arr(t: Tensor) -> np.ndarray:
            return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32)

        return PillarWeights(
            raw_t=arr(raw.t()), pillar=arr(per_pillar), sign=arr(sign), scale=arr(scale),
            shift=arr(shift),
        )  # fmt: skip

    def _encode_one(self, cloud: Tensor) -> Tensor:
        """:meth:`forward` of one CPU cloud ``(N, F)`` in eval mode: ``(1, C, H, W)``."""
        g = self.grid
        bounds = (g.x_min, g.x_max, g.y_min, g.y_max, self.z_min, self.z_max)
        return encode_cloud(
            cloud.reshape(-1, self.num_features), self.kernel_weights(), bounds, g.cell,
            g.shape, self.max_points,
        )  # fmt: skip

    def _pillar_points(self, pillars: Pillars) -> tuple[Tensor, Tensor]:
        """``(P, 3)`` mean of each pillar's kept points and ``(P, 3)`` its geometric centre."""
        pts = pillars.points
        sums = torch.zeros(pillars.keys.numel(), 3, device=pts.device, dtype=pts.dtype)
        sums.index_add_(0, pillars.pillar_of_point, pts[:, :3])
        mean = sums / pillars.counts.unsqueeze(1).to(pts.dtype)
        ny, nx = self.grid.shape
        col = (pillars.keys % nx).to(pts.dtype)
        row = ((pillars.keys // nx) % ny).to(pts.dtype)
        centre = torch.stack(
            [
                self.grid.x_min + (col + 0.5) * self.grid.cell,
                self.grid.y_min + (row + 0.5) * self.grid.cell,
                torch.full_like(col, 0.5 * (self.z_min + self.z_max)),
            ],
            dim=1,
        )
        return mean, centre

    def forward(self, clouds: Sequence[Tensor]) -> Tensor:
        """Encode a batch of clouds.

        Args:
            clouds: ``B`` tensors ``(N_b, F)``, LiDAR frame, finite (validated by the caller).

        Returns:
            ``(B, C, H, W)`` BEV canvas, rows ``iy`` (+y), columns ``ix`` (+x); zero where empty.
        """
        for i, c in enumerate(clouds):
            if c.dim() != 2 or c.shape[1] != self.num_features:
                raise ValueError(
                    f"PillarEncoder: cloud {i} must have shape (N, {self.num_features}), "
                    f"got {tuple(c.shape)}"
                )
        if (
            len(clouds) == 1
            and clouds[0].device.type == "cpu"
            and not self.norm.training
            and not torch.is_grad_enabled()
        ):  # one cloud at inference (the app, encode_scene): one compiled pass
            return self._encode_one(clouds[0])
        pillars = voxelize(clouds, self.grid, self.z_min, self.z_max, self.max_points)
        ny, nx = self.grid.shape
        channels = self.out_channels
        device = self.linear.weight.device
        # The canvas is built channel-major, ``(C, B * H * W)``: for one cloud (the app) the final
        # ``(B, C, H, W)`` is then a view, with no transposing copy of the whole grid.
        if pillars.keys.numel() == 0:
            canvas = torch.zeros(channels, pillars.batch_size * ny * nx, device=device)
        else:
            pooled = self._pooled(pillars)
            canvas = torch.zeros(
                channels, pillars.batch_size * ny * nx, device=device, dtype=pooled.dtype
            )
            # (a contiguous source: the copy is column runs, not 32 strided reads per pillar)
            canvas.index_copy_(1, pillars.keys, pooled.t().contiguous())
        return canvas.view(channels, pillars.batch_size, ny, nx).permute(1, 0, 2, 3).contiguous()
