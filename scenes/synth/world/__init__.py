"""The synthetic driving world: a road with kerbs, buildings and street clutter, plus actors, as
triangle meshes in the LiDAR frame, and first-hit ray casting against it with embree.

Frame and time
    Everything is in the LiDAR frame at the frame's time stamp ``t = 0`` (x forward, y left, z up,
    metres, origin at the LiDAR). The ground plane is ``z = -lidar_height``. The ego vehicle drives
    along +x at ``ego_speed`` without yaw rate, so at time ``t`` the ego (and every sensor on it) sits
    ``ego_speed * t`` further along x, and an actor's mesh is translated by ``velocity * t``: that is
    how older radar scans are simulated (:meth:`World.actor_mesh_at`).

Streets
    Delft-like city streets (calibrated to View-of-Delft, issue 14): mostly one narrow lane each
    way, raised cycle paths or red cycle lanes on most sides, few cars and many cyclists and
    pedestrians (a median of 10 referable road users per frame, about 80 % of them cyclists
    and pedestrians; docs/SENSOR_STATS.md), and parked bicycles, bicycle racks and mopeds on verges and sidewalks.
    Those are :class:`Clutter`: static geometry that both sensors see but that is never an
    :class:`~scenes.geometry.actors.Actor`, so never a referent nor in ``label_2``; :attr:`World.clutter`
    records their VoD class and box.

Road
    A centreline ``y = offset + curvature * u**2 / 2`` (``u`` = x; gently curved, radius >= 300 m,
    or straight), with a lateral profile of bands (lanes, markings, parking, kerb, verge, bike path,
    sidewalk, yard) extruded along it: the carriageway is at ground level, everything beyond the
    kerbs is raised by ``kerb_height``. Right-hand traffic: the ego's lanes lie right of the
    centreline (``s < 0``), oncoming lanes left of it. Buildings, walls and hedges line the road
    beyond the yards; street lights, signs, bollards and trees stand in the verges.

Actors
    Cars (body + cabin + wheels), pedestrians (legs, torso, arms, head) and cyclists (bicycle +
    rider) are built in their own box frame and scaled so that their axis-aligned bounds are exactly
    the sampled ``l, w, h``: the :class:`~scenes.geometry.actors.Actor` box is the tight box of the mesh, with
    ``z`` at its geometric centre (a pedestrian on a sidewalk stands ``kerb_height`` higher).
    Velocities are ground velocities along the heading (cars 0..15 m/s in lanes, both directions, or
    parked; pedestrians 0..2 m/s along sidewalks or crossing; cyclists 2..7 m/s). Actor boxes never
    overlap each other, the ego vehicle, or the trunks and poles.

Class sets
    ``WorldConfig.classes`` (``--classes``) picks the road users: ``vod`` (the default: cars,
    pedestrians, cyclists, draw for draw as before class sets) or ``nuscenes`` (nuScenes' 10
    detection classes: road works with cones, barriers and construction vehicles, buses at stops
    or in lanes, trucks parked, moving or towing a trailer, parked trailers, ridden and parked
    motorcycles, ridden bicycles, cars and pedestrians; the street clutter's parked bicycles and
    mopeds become ``Bicycle`` and ``Motorcycle`` actors). :mod:`~scenes.synth.world.road_users`
    holds the plans and the world facts of the new classes.

Materials
    Each face carries a :class:`Mat` (LiDAR reflectivity, radar behaviour of static surfaces) and
    an owner (actor index, or -1 for static geometry). The sensors read both from :class:`RayHits`.

Determinism: :func:`generate_world` draws everything from the generator it is given; the same seed
gives the same world, bit for bit.

Modules (each imports only ones listed before it, and ``scenes.geometry.actors`` / ``scenes.geometry.calib``)
    :mod:`~scenes.synth.world.materials` surface materials and their sensor properties;
    :mod:`~scenes.synth.world.meshes` tagged triangle meshes and primitive parts;
    :mod:`~scenes.synth.world.actor_meshes` cars, pedestrians, cyclists;
    :mod:`~scenes.synth.world.road` the street layout and its mesh;
    :mod:`~scenes.synth.world.footprint` BEV footprints and their overlap test;
    :mod:`~scenes.synth.world.roadside` buildings, walls, hedges, lights, signs, bollards, trees;
    :mod:`~scenes.synth.world.clutter` parked bicycles, bicycle racks, mopeds;
    :mod:`~scenes.synth.world.street` the roadside as drawn per kind, and streets of other
    densities (:class:`~scenes.synth.world.config.StreetDensity`, drawn after the actors);
    :mod:`~scenes.synth.world.placement` actor candidates, sizes and margins;
    :mod:`~scenes.synth.world.road_user_meshes` trucks, buses, trailers, construction vehicles,
    motorcycles, cones, barriers; :mod:`~scenes.synth.world.road_users` the plans per class set;
    :mod:`~scenes.synth.world.config` :class:`WorldConfig`; :mod:`~scenes.synth.world.scene` :class:`World`;
    :mod:`~scenes.synth.world.generate` :func:`generate_world`; :mod:`~scenes.synth.world.raycast`
    :class:`RayCaster`. This package re-exports their public names.
"""

from scenes.synth.world.actor_meshes import (
    CAR_SIZE,
    CYCLIST_SIZE,
    PEDESTRIAN_SIZE,
    RIDER_IN_CYCLIST,
    bicycle_parts,
    car_mesh,
    cyclist_mesh,
    pedestrian_mesh,
    rider_boxes,
)
from scenes.synth.world.clutter import BICYCLE_SIZE, MOPED_SIZE, RACK_SLOT, Clutter, moped_mesh
from scenes.synth.world.config import WorldConfig
from scenes.synth.world.footprint import Obstacle
from scenes.synth.world.generate import generate_world
from scenes.synth.world.materials import (
    LIDAR_DEPTH_JITTER,
    LIDAR_DROPOUT,
    MATERIALS,
    RADAR_PROB,
    RADAR_RCS,
    REFLECTIVITY,
    Mat,
    Material,
)
from scenes.synth.world.meshes import (
    TaggedMesh,
    box_part,
    cylinder_part,
    ellipsoid_part,
    hexahedron_part,
)
from scenes.synth.world.placement import EGO_FOOTPRINT
from scenes.synth.world.raycast import RayCaster, RayHits
from scenes.synth.world.road import U_RANGE, Band, Road, Side, make_road, road_mesh
from scenes.synth.world.scene import World

__all__ = [
    "BICYCLE_SIZE",
    "CAR_SIZE",
    "CYCLIST_SIZE",
    "EGO_FOOTPRINT",
    "LIDAR_DEPTH_JITTER",
    "LIDAR_DROPOUT",
    "MATERIALS",
    "MOPED_SIZE",
    "PEDESTRIAN_SIZE",
    "RACK_SLOT",
    "RADAR_PROB",
    "RADAR_RCS",
    "REFLECTIVITY",
    "RIDER_IN_CYCLIST",
    "U_RANGE",
    "Band",
    "Clutter",
    "Mat",
    "Material",
    "Obstacle",
    "RayCaster",
    "RayHits",
    "Road",
    "Side",
    "TaggedMesh",
    "World",
    "WorldConfig",
    "bicycle_parts",
    "box_part",
    "car_mesh",
    "cyclist_mesh",
    "cylinder_part",
    "ellipsoid_part",
    "generate_world",
    "hexahedron_part",
    "make_road",
    "moped_mesh",
    "pedestrian_mesh",
    "rider_boxes",
    "road_mesh",
]
