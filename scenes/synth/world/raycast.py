"""First-hit ray casting against a :class:`~scenes.synth.world.scene.World` with trimesh's embree
intersector: the static scene is built once, the actors' scene once per queried time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from trimesh.ray.ray_pyembree import RayMeshIntersector

from scenes.synth.world.meshes import TaggedMesh
from scenes.synth.world.scene import World


@dataclass(frozen=True)
class RayHits:
    """First hits of a batch of ``R`` rays.

    Attributes:
        hit: ``(R,)`` bool.
        distance: ``(R,)`` metres along the unit direction (inf where no hit).
        points: ``(R, 3)`` hit points, LiDAR frame (NaN where no hit).
        cos_incidence: ``(R,)`` ``|cos|`` of the angle between the ray and the face normal.
        material: ``(R,)`` :class:`Mat` value (-1 where no hit).
        owner: ``(R,)`` actor index, -1 for static geometry (and where no hit).
    """

    hit: np.ndarray
    distance: np.ndarray
    points: np.ndarray
    cos_incidence: np.ndarray
    material: np.ndarray
    owner: np.ndarray


class _MeshCaster:
    """First-hit queries on one :class:`TaggedMesh` through trimesh's embree intersector."""

    def __init__(self, mesh: TaggedMesh) -> None:
        self.mesh = mesh
        self.empty = len(mesh.faces) == 0
        if self.empty:
            return
        self.intersector = RayMeshIntersector(mesh.to_trimesh())
        tri = mesh.vertices[mesh.faces]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(normal, axis=1, keepdims=True)
        self.normal = normal / np.where(norm > 0, norm, 1.0)
        self.anchor = tri[:, 0]

    def cast(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(R,)`` triangle index (-1 = miss) and distance (inf = miss)."""
        r = len(origins)
        if self.empty or r == 0:
            return np.full(r, -1), np.full(r, np.inf)
        tri = np.asarray(self.intersector.intersects_first(origins, dirs), dtype=np.int64)
        dist = np.full(r, np.inf)
        ok = tri >= 0
        n = self.normal[tri[ok]]
        denom = np.einsum("ij,ij->i", dirs[ok], n)
        num = np.einsum("ij,ij->i", self.anchor[tri[ok]] - origins[ok], n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / denom
        t[~np.isfinite(t) | (np.abs(denom) < 1e-12) | (t < 0)] = np.inf
        dist[ok] = t
        tri[~np.isfinite(dist)] = -1
        return tri, dist


class RayCaster:
    """First-hit ray casting against a :class:`World` at a time offset.

    The static geometry's embree scene is built once; the actors' scene once per queried time
    (actors move, the static world does not).
    """

    def __init__(self, world: World) -> None:
        self.world = world
        self._static = _MeshCaster(world.static_mesh)
        self._actors: dict[float, _MeshCaster] = {}

    @property
    def uses_embree(self) -> bool:
        """True when the intersector is trimesh's embree one (it always is: no fallback)."""
        return self._static.empty or isinstance(self._static.intersector, RayMeshIntersector)

    def _actor_caster(self, time: float) -> _MeshCaster:
        key = round(float(time), 6)
        if key not in self._actors:
            self._actors[key] = _MeshCaster(self.world.actor_mesh_at(key))
        return self._actors[key]

    def cast(self, origins: np.ndarray, dirs: np.ndarray, time: float = 0.0) -> RayHits:
        """Cast rays ``origins (R, 3)`` along unit ``dirs (R, 3)`` (LiDAR frame of ``t = 0``) at
        ``time`` (the actors' positions; the caller places the origins)."""
        origins = np.ascontiguousarray(origins, dtype=np.float64)
        dirs = np.ascontiguousarray(dirs, dtype=np.float64)
        s_tri, s_dist = self._static.cast(origins, dirs)
        dyn = self._actor_caster(time)
        a_tri, a_dist = dyn.cast(origins, dirs)
        use_actor = a_dist < s_dist
        dist = np.where(use_actor, a_dist, s_dist)
        hit = np.isfinite(dist)
        r = len(origins)
        material = np.full(r, -1, np.int64)
        owner = np.full(r, -1, np.int64)
        cos_inc = np.zeros(r)
        sel = hit & ~use_actor
        if sel.any():
            material[sel] = self._static.mesh.material[s_tri[sel]]
            cos_inc[sel] = np.abs(np.einsum("ij,ij->i", dirs[sel], self._static.normal[s_tri[sel]]))
        sel = hit & use_actor
        if sel.any():
            material[sel] = dyn.mesh.material[a_tri[sel]]
            owner[sel] = dyn.mesh.owner[a_tri[sel]]
            cos_inc[sel] = np.abs(np.einsum("ij,ij->i", dirs[sel], dyn.normal[a_tri[sel]]))
        points = origins + dirs * np.where(hit, dist, np.nan)[:, None]
        return RayHits(hit, dist, points, cos_inc, material, owner)
