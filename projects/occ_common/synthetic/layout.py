"""Procedural layout of one synthetic scene's world.

:func:`build_world` places, from a seeded random generator, the street
furniture of a nuScenes-like urban street (see :mod:`.world` for the frame
conventions): cross streets and flat patches in the ground, buildings set
back behind the sidewalks, trees and hedges on the verges, parked vehicles
along both kerbs, a construction zone with cones, barriers and a
construction vehicle, traffic in four lanes (a lead car in the ego's lane),
pedestrians, bicycles and benches on the sidewalks.

Every scene shows each object class near the ego's path (see
:data:`_ALWAYS_NEAR`): the random draws alone leave the rare ones (a bus
in one scene of four, a trailer in one of three) out of a small world's
validation scenes, where mIoU then cannot measure them.

Nothing ever enters the ego's lane except the lead car, which drives at the
ego's mean speed, so the sensors never start inside an object.
"""
from typing import Dict, List, Tuple

import numpy as np

from .world import Boxes, EgoMotion, RoadLayout, World

# Raw nuScenes-lidarseg indices of the objects the layout places.
RAW_PEDESTRIAN = 2
RAW_BARRIER = 9
RAW_CONE = 12
RAW_BICYCLE = 14
RAW_BUS = 16
RAW_CAR = 17
RAW_CONSTRUCTION = 18
RAW_MOTORCYCLE = 21
RAW_TRAILER = 22
RAW_TRUCK = 23
RAW_MANMADE = 28
RAW_STATIC_OTHER = 29
RAW_VEGETATION = 30

# (length, width, height) ranges in metres, close to nuScenes' averages.
_SIZES: Dict[int, Tuple[Tuple[float, float], ...]] = {
    RAW_CAR: ((4.2, 4.9), (1.8, 2.0), (1.45, 1.75)),
    RAW_TRUCK: ((6.0, 8.5), (2.3, 2.6), (2.8, 3.4)),
    RAW_BUS: ((11.0, 12.5), (2.8, 3.0), (3.2, 3.6)),
    RAW_CONSTRUCTION: ((5.5, 6.5), (2.6, 2.9), (3.0, 3.4)),
    RAW_TRAILER: ((9.0, 11.0), (2.5, 2.7), (3.5, 3.9)),
    RAW_MOTORCYCLE: ((2.0, 2.2), (0.75, 0.85), (1.3, 1.5)),
    RAW_BICYCLE: ((1.6, 1.8), (0.55, 0.65), (1.1, 1.25)),
    RAW_PEDESTRIAN: ((0.6, 0.8), (0.6, 0.7), (1.6, 1.9)),
    RAW_CONE: ((0.4, 0.45), (0.4, 0.45), (0.7, 0.8)),
    RAW_BARRIER: ((2.0, 2.3), (0.5, 0.6), (0.9, 1.05)),
    RAW_STATIC_OTHER: ((1.6, 2.0), (0.5, 0.7), (0.8, 1.0)),
}

# Instance colour palettes (RGB albedo); textures add per-class patterns.
_PALETTES: Dict[int, Tuple[Tuple[float, float, float], ...]] = {
    RAW_CAR: ((0.70, 0.10, 0.10), (0.12, 0.22, 0.60), (0.85, 0.85, 0.85),
              (0.09, 0.09, 0.10), (0.60, 0.62, 0.65), (0.10, 0.35, 0.20)),
    RAW_TRUCK: ((0.92, 0.92, 0.90), (0.85, 0.75, 0.20), (0.20, 0.35, 0.65)),
    RAW_BUS: ((0.85, 0.35, 0.10), (0.80, 0.15, 0.15)),
    RAW_CONSTRUCTION: ((0.92, 0.72, 0.08), ),
    RAW_TRAILER: ((0.62, 0.62, 0.64), (0.75, 0.72, 0.68)),
    RAW_MOTORCYCLE: ((0.10, 0.10, 0.12), (0.55, 0.05, 0.05)),
    RAW_BICYCLE: ((0.55, 0.12, 0.12), (0.15, 0.30, 0.55)),
    RAW_PEDESTRIAN: ((0.15, 0.15, 0.35), (0.55, 0.15, 0.15),
                     (0.20, 0.45, 0.25), (0.75, 0.70, 0.30)),
    RAW_CONE: ((1.00, 0.45, 0.05), ),
    RAW_BARRIER: ((0.90, 0.15, 0.12), ),
    RAW_STATIC_OTHER: ((0.42, 0.30, 0.18), ),
    RAW_MANMADE: ((0.78, 0.70, 0.55), (0.62, 0.30, 0.22), (0.55, 0.56, 0.58),
                  (0.85, 0.82, 0.75)),
    RAW_VEGETATION: ((0.14, 0.36, 0.13), (0.20, 0.42, 0.15)),
}

#: Lanes ``(v, direction)``: two with the ego's travel direction (the ego
#: drives in v = -1.75), two oncoming.
_LANES = ((-1.75, 1), (-4.75, 1), (1.75, -1), (4.75, -1))
# Parked vehicles (up to 2.7 m wide) stay clear of a 3 m wide bus in the
# outer lane and on the 8.5 m half-width street.
_PARKING_V = 7.2
_TRUNK_COLOUR = (0.30, 0.20, 0.10)
#: Metres around the ego's mid-scene position within which each scene
#: places one of every rare object class (a parked trailer and motorcycle,
#: a bus and a motorcycle in traffic, a bicycle and a bench): well inside
#: the 40 m (Occ3D) and 50 m (SurroundOcc) label ranges for the scene's
#: whole length.
_ALWAYS_NEAR = 20.0


class _BoxList:
    """Accumulates boxes in road-frame terms, then converts to global."""

    def __init__(self, layout: RoadLayout, rng: np.random.Generator):
        self.layout = layout
        self.rng = rng
        self.rows: List[tuple] = []

    def add(self, raw_class: int, u: float, v: float, size: tuple,
            rel_yaw: float = 0.0, z_bottom: float = 0.0,
            speed_u: float = 0.0, annotated: bool = True,
            attribute: str = '', colour: tuple = None) -> None:
        """Adds one box standing at ``(u, v)`` (road frame)."""
        if colour is None:
            palette = _PALETTES[raw_class]
            colour = palette[self.rng.integers(len(palette))]
        self.rows.append((raw_class, u, v, tuple(size), rel_yaw, z_bottom,
                          speed_u, annotated, attribute, tuple(colour)))

    def sample_size(self, raw_class: int) -> tuple:
        """Draws a (length, width, height) for a class."""
        return tuple(self.rng.uniform(lo, hi) for lo, hi in _SIZES[raw_class])

    def to_boxes(self) -> Boxes:
        """Converts the accumulated rows into global :class:`Boxes`."""
        rows = self.rows
        u = np.array([r[1] for r in rows], dtype=np.float64)
        v = np.array([r[2] for r in rows], dtype=np.float64)
        size = np.array([r[3] for r in rows], dtype=np.float64).reshape(-1, 3)
        z = np.array([r[5] for r in rows], dtype=np.float64) + size[:, 2] / 2
        heading = self.layout.heading
        speed = np.array([r[6] for r in rows], dtype=np.float64)
        velocity = np.stack([speed * np.cos(heading),
                             speed * np.sin(heading)], axis=1)
        center = np.concatenate(
            [self.layout.to_global(u, v).reshape(-1, 2), z[:, None]], axis=1)
        yaw = np.array([r[4] for r in rows], dtype=np.float64) + heading
        return Boxes(
            center=center, size=size,
            yaw=np.arctan2(np.sin(yaw), np.cos(yaw)),
            velocity=velocity.reshape(-1, 2),
            raw_class=np.array([r[0] for r in rows], dtype=np.uint8),
            colour=np.array([r[9] for r in rows]).reshape(-1, 3),
            annotated=np.array([r[7] for r in rows], dtype=bool),
            attribute=[r[8] for r in rows])


def _free(layout: RoadLayout, u: float, v: float, half_length: float,
          margin: float = 2.0) -> bool:
    """Whether a stretch centred at ``u`` avoids cross streets and patches."""
    us = np.array([u - half_length, u, u + half_length])
    if layout.in_cross_street(us, margin).any():
        return False
    return not layout.in_flat_patch(us, np.full(3, v), margin).any()


def _take_rare(u: float, rare, rare_from: float, step: float):
    """Whether the slot at ``u`` takes the pending rare object, and the
    slot's start: the last slot before ``rare_from`` (slots being at most
    ``step`` apart) moves up to ``rare_from``, so the rare object starts
    there rather than up to a step later."""
    if rare is None or u < rare_from - step:
        return False, u
    return True, max(u, rare_from)


def _place_static(boxes: _BoxList, u_range: Tuple[float, float],
                  zone: Tuple[float, float, int], focus: float) -> None:
    """Buildings, trees, hedges, parked vehicles and sidewalk furniture;
    a parked trailer on one side and a parked motorcycle on the other, a
    bicycle and a bench, each within :data:`_ALWAYS_NEAR` of ``focus``."""
    layout, rng = boxes.layout, boxes.rng
    kerb = layout.road_half_width + layout.sidewalk_width
    # Opposite the construction zone, which would push it away.
    trailer_side = -zone[2]
    for side in (-1, 1):
        u = u_range[0] + rng.uniform(0, 6)
        while u < u_range[1]:  # buildings
            length = rng.uniform(8, 25)
            center = u + length / 2
            # Set back behind the trees' crowns.
            front, depth = rng.uniform(17, 22.5), rng.uniform(8, 14)
            if _free(layout, center, side * (front + 1), length / 2, 3.0):
                boxes.add(RAW_MANMADE, center, side * (front + depth / 2),
                          (length, depth, rng.uniform(5, 18)),
                          annotated=False)
            u += length + rng.uniform(2, 9)
        u = u_range[0] + rng.uniform(0, 8)
        while u < u_range[1]:  # trees: a trunk and a crown
            v = side * rng.uniform(kerb + 0.8, kerb + 2.2)
            if _free(layout, u, v, 2.0):
                boxes.add(RAW_VEGETATION, u, v, (0.35, 0.35, 2.4),
                          annotated=False, colour=_TRUNK_COLOUR)
                crown = rng.uniform(2.5, 4.0)
                boxes.add(RAW_VEGETATION, u, v, (crown, crown,
                                                 rng.uniform(2.5, 3.5)),
                          rel_yaw=rng.uniform(0, np.pi / 2), z_bottom=2.2,
                          annotated=False)
            elif rng.random() < 0.5 and _free(layout, u, side * (kerb + 3),
                                              5.0):
                boxes.add(RAW_VEGETATION, u, side * (kerb + 3),
                          (rng.uniform(4, 9), 0.9, 1.2), annotated=False)
            u += rng.uniform(9, 16)
        # The first free parking place past a random point near the focus
        # gets this side's rare vehicle.
        rare = RAW_TRAILER if side == trailer_side else RAW_MOTORCYCLE
        rare_from = focus + rng.uniform(-_ALWAYS_NEAR, _ALWAYS_NEAR / 2)
        for _ in range(8):  # clear of the cross streets (120 m apart)
            if not layout.in_cross_street(np.array(rare_from + 6.0), 9.0):
                break
            rare_from = focus + rng.uniform(-_ALWAYS_NEAR, _ALWAYS_NEAR / 2)
        u = u_range[0] + rng.uniform(0, 5)
        while u < u_range[1]:  # parked vehicles along the kerb
            # Slots advance by a vehicle (<= 11 m) and a 1.2-4 m gap.
            forced, u = _take_rare(u, rare, rare_from, 15.0)
            kind = rare if forced else rng.choice(
                [RAW_CAR, RAW_TRUCK, RAW_MOTORCYCLE, RAW_TRAILER],
                p=[0.8, 0.1, 0.05, 0.05])
            size = boxes.sample_size(kind)
            center = u + size[0] / 2
            # The zone and its construction vehicle (parked just after it).
            in_zone = (zone[2] == side
                       and zone[0] - 6 < center < zone[1] + 14)
            if ((forced or rng.random() < 0.6) and not in_zone
                    and not layout.in_cross_street(np.array(center), 3.0)):
                if forced:
                    rare = None
                v = side * (_PARKING_V + (0.5 if kind == RAW_MOTORCYCLE
                                          else 0.0))
                attribute = ('cycle.without_rider' if kind == RAW_MOTORCYCLE
                             else 'vehicle.parked')
                # Parked with the traffic of their side of the street.
                yaw = 0.0 if side < 0 else np.pi
                boxes.add(kind, center, v, size, rel_yaw=yaw,
                          attribute=attribute)
            u += size[0] + rng.uniform(1.2, 4.0)
        # One side's first sidewalk place past the focus gets a bicycle,
        # the other side's a bench.
        rare = RAW_BICYCLE if side == trailer_side else RAW_STATIC_OTHER
        rare_from = focus + rng.uniform(-_ALWAYS_NEAR, _ALWAYS_NEAR / 2)
        u = u_range[0] + rng.uniform(0, 10)
        while u < u_range[1]:  # bicycles and benches on the sidewalk
            # Along the sidewalk's outer edge, clear of the pedestrians.
            v = side * (kerb - 0.45)
            forced, u = _take_rare(u, rare, rare_from, 25.0)
            if not layout.in_cross_street(np.array(u), 2.0):
                if forced:
                    bicycle, rare = rare == RAW_BICYCLE, None
                else:
                    bicycle = rng.random() < 0.5
                if bicycle:
                    boxes.add(RAW_BICYCLE, u, v,
                              boxes.sample_size(RAW_BICYCLE),
                              rel_yaw=rng.uniform(-0.05, 0.05),
                              attribute='cycle.without_rider')
                else:
                    boxes.add(RAW_STATIC_OTHER, u, v,
                              boxes.sample_size(RAW_STATIC_OTHER),
                              annotated=False)
            u += rng.uniform(12, 25)


def _place_construction_zone(boxes: _BoxList,
                             zone: Tuple[float, float, int]) -> None:
    """Cones and barriers closing the parking lane, a construction
    vehicle after them."""
    start, end, side = zone
    crossing = boxes.layout.in_cross_street
    for u in np.arange(start, end, 3.0):
        if not crossing(np.array(u), 1.0):
            boxes.add(RAW_CONE, u, side * (_PARKING_V - 0.5),
                      boxes.sample_size(RAW_CONE),
                      rel_yaw=boxes.rng.uniform(0, np.pi))
    for u in np.arange(start + 1.2, end, 2.5):
        if not crossing(np.array(u), 2.0):
            boxes.add(RAW_BARRIER, u,
                      side * (boxes.layout.road_half_width - 0.5),
                      boxes.sample_size(RAW_BARRIER))
    size = boxes.sample_size(RAW_CONSTRUCTION)
    boxes.add(RAW_CONSTRUCTION, end + size[0] / 2 + 1.0,
              side * (_PARKING_V + 0.1),
              size, rel_yaw=0.0 if side < 0 else np.pi,
              attribute='vehicle.stopped')


def _place_traffic(boxes: _BoxList, ego: EgoMotion, duration: float,
                   u_range: Tuple[float, float], focus: float) -> None:
    """Moving vehicles in the four lanes, then the pedestrians; a bus in
    the inner oncoming lane and a motorcycle in the ego's outer lane pass
    within :data:`_ALWAYS_NEAR` of ``focus`` at mid-scene."""
    rng = boxes.rng
    mean_speed = ego.speed + 0.5 * ego.accel * duration
    rare_vehicle = {1.75: RAW_BUS, -4.75: RAW_MOTORCYCLE}
    for lane_v, direction in _LANES:
        if lane_v == ego.lane_v:
            # A lead car at the ego's mean speed keeps a safe gap.
            size = boxes.sample_size(RAW_CAR)
            gap = rng.uniform(12, 20) + size[0] / 2
            boxes.add(RAW_CAR, ego.u0 + gap, lane_v, size,
                      speed_u=mean_speed, attribute='vehicle.moving')
            continue
        # Heavy vehicles only in the inner oncoming lane: in the outer lanes
        # they would graze the parked vehicles.
        heavy = lane_v == 1.75
        kinds, odds = ([RAW_CAR, RAW_TRUCK, RAW_BUS, RAW_MOTORCYCLE],
                       [0.75, 0.13, 0.08, 0.04]) if heavy else (
                           [RAW_CAR, RAW_MOTORCYCLE], [0.92, 0.08])
        # One speed per lane: vehicles never catch up with each other.
        speed = rng.uniform(4.0, 10.0)
        rare = rare_vehicle.get(lane_v)
        # Where the rare vehicle starts so that it is near the focus at
        # mid-scene.
        rare_from = (focus + rng.uniform(-_ALWAYS_NEAR, _ALWAYS_NEAR / 2)
                     - direction * speed * duration / 2)
        # Spawn far enough out that traffic stays around the ego.
        u = u_range[0] - speed * duration + rng.uniform(0, 10)
        while u < u_range[1] + speed * duration:
            # Slots advance by a vehicle (<= 12.5 m) and a 10-35 m gap.
            forced, u = _take_rare(u, rare, rare_from, 47.5)
            if forced:
                kind, rare = rare, None
            else:
                kind = rng.choice(kinds, p=odds)
            size = boxes.sample_size(kind)
            boxes.add(kind, u + size[0] / 2, lane_v, size,
                      rel_yaw=0.0 if direction > 0 else np.pi,
                      speed_u=direction * speed,
                      attribute=('cycle.with_rider' if kind == RAW_MOTORCYCLE
                                 else 'vehicle.moving'))
            u += size[0] + rng.uniform(10, 35)
    _place_pedestrians(boxes, duration, u_range)


def _place_pedestrians(boxes: _BoxList, duration: float,
                       u_range: Tuple[float, float]) -> None:
    """Pedestrians on both sidewalks: standing ones near the kerb, walkers
    in one band per direction, each band at one speed so nobody walks
    through anybody."""
    rng, layout = boxes.rng, boxes.layout
    edge = layout.road_half_width
    for side in (-1, 1):
        u = u_range[0] + rng.uniform(0, 8)
        while u < u_range[1]:
            boxes.add(RAW_PEDESTRIAN, u, side * (edge + 0.55),
                      boxes.sample_size(RAW_PEDESTRIAN),
                      rel_yaw=rng.uniform(-np.pi, np.pi),
                      attribute='pedestrian.standing')
            u += rng.uniform(12, 30)
        for direction, offset in ((1, 1.45), (-1, 2.25)):
            speed = rng.uniform(0.9, 1.6)
            u = u_range[0] - speed * duration + rng.uniform(0, 8)
            while u < u_range[1] + speed * duration:
                boxes.add(RAW_PEDESTRIAN, u, side * (edge + offset),
                          boxes.sample_size(RAW_PEDESTRIAN),
                          rel_yaw=0.0 if direction > 0 else np.pi,
                          speed_u=direction * speed,
                          attribute='pedestrian.moving')
                u += rng.uniform(10, 25)


def build_world(rng: np.random.Generator, duration: float, is_rainy: bool,
                is_night: bool, margin: float = 75.0) -> World:
    """Builds the world of one scene.

    Args:
        rng (np.random.Generator): Source of every random choice; the same
            generator state gives the same world.
        duration (float): Seconds the scene lasts (first to last sweep).
        is_rainy (bool): Whether the scene is rainy.
        is_night (bool): Whether the scene is at night.
        margin (float): Metres of world kept around the ego's path, beyond
            the 50 m occupancy range. Defaults to 75.

    Returns:
        World: The scene's world.
    """
    if duration < 0:
        raise ValueError(f'Expected a duration >= 0 s, got {duration}.')
    heading = rng.uniform(-np.pi, np.pi)
    speed = rng.uniform(4.0, 8.0)
    # Bound the acceleration so the lead car's gap changes by < 4 m.
    accel = float(np.clip(rng.uniform(-0.3, 0.3), -8 / max(duration, 1) ** 2,
                          8 / max(duration, 1) ** 2))
    ego = EgoMotion(u0=0.0, speed=speed, accel=accel, lane_v=_LANES[0][0],
                    weave_amp=rng.uniform(0.1, 0.3),
                    weave_freq=rng.uniform(0.4, 0.8),
                    weave_phase=rng.uniform(0, 2 * np.pi))
    u_end = ego.road_state(duration)[0]
    u_range = (-margin, u_end + margin)
    first_cross = rng.uniform(18, 40)
    crosses = np.concatenate([
        np.arange(first_cross, u_range[1], 120.0),
        np.arange(first_cross - 120.0, u_range[0], -120.0)])
    patches = []
    for side in (-1, 1):
        for _ in range(rng.integers(1, 3)):
            u0 = rng.uniform(u_range[0], u_range[1] - 16)
            kerb = RoadLayout.road_half_width + RoadLayout.sidewalk_width
            near, far = kerb, kerb + rng.uniform(6, 12)
            v0, v1 = (near, far) if side > 0 else (-far, -near)
            patches.append((u0, u0 + rng.uniform(8, 16), v0, v1))
    # Start the ego far enough from the global origin that the whole world
    # has positive coordinates, as nuScenes' map rasters require.
    reach = u_range[1] + 50.0
    origin = (reach, reach)
    road_origin = np.asarray(origin, dtype=np.float64) - np.array(
        [np.cos(heading), np.sin(heading)]) * ego.u0 + np.array(
            [np.sin(heading), -np.cos(heading)]) * ego.lane_v
    layout = RoadLayout(origin=road_origin, heading=heading,
                        cross_streets=np.sort(crosses),
                        flat_patches=np.array(patches).reshape(-1, 4))
    zone_start = rng.uniform(10, 40)
    zone = (zone_start, zone_start + rng.uniform(12, 20),
            int(rng.choice([-1, 1])))
    boxes = _BoxList(layout, rng)
    focus = ego.road_state(duration / 2)[0]
    _place_static(boxes, u_range, zone, focus)
    _place_construction_zone(boxes, zone)
    _place_traffic(boxes, ego, duration, u_range, focus)
    parts = (['Night'] if is_night else []) + (['rain'] if is_rainy else [])
    parts += ['parked cars', 'peds on sidewalk', 'construction zone',
              'intersection']
    description = ', '.join(parts)
    description = description[0].upper() + description[1:]
    sun = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), 0.8])
    return World(layout=layout, boxes=boxes.to_boxes(), ego=ego,
                 is_rainy=is_rainy, is_night=is_night,
                 description=description,
                 sun_direction=sun / np.linalg.norm(sun))
