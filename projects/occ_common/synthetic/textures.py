"""Per-class albedo, texture patterns and lighting of rendered images.

Every class gets a base colour and a procedural pattern computed from the
hit point's coordinates (lane markings and asphalt grain on the road, tiles
on sidewalks, bricks on other flat ground, window grids on buildings, glass
bands on vehicles, stripes on barriers and cones, blotchy foliage, ...), so
that a network can tell classes apart from pixels alone. Lighting is
Lambertian: a sun and an ambient term by day, an overcast sky in rain, and
at night the ego's headlights, street lamps and lit windows.
"""
import numpy as np

from .raycast import TARGET_GROUND, RayHits
from .world import (RAW_DRIVEABLE, RAW_OTHER_FLAT, RAW_SIDEWALK, RAW_TERRAIN,
                    World)

_GROUND_COLOURS = {
    RAW_DRIVEABLE: (0.28, 0.28, 0.30),
    RAW_OTHER_FLAT: (0.55, 0.38, 0.30),
    RAW_SIDEWALK: (0.62, 0.60, 0.57),
    RAW_TERRAIN: (0.32, 0.45, 0.18),
}
_GLASS = np.array([0.08, 0.10, 0.14])
_WHITE = np.array([0.92, 0.92, 0.90])
_DARK = np.array([0.07, 0.07, 0.08])
_SKIN = np.array([0.85, 0.65, 0.50])
_WINDOW_LIGHT = np.array([1.0, 0.80, 0.45])


def value_noise(points: np.ndarray, scale: float, seed: int = 0
                ) -> np.ndarray:
    """Blocky value noise in [0, 1): one hashed value per cube of side
    ``scale``.

    Args:
        points (np.ndarray): Positions. Shape (R, 3).
        scale (float): Cell size in metres.
        seed (int): Decorrelates independent noise layers. Defaults to 0.

    Returns:
        np.ndarray: Noise values. Shape (R,).
    """
    cells = np.floor(points / scale).astype(np.int64)
    h = (cells[:, 0] * 73856093) ^ (cells[:, 1] * 19349663) ^ (
        cells[:, 2] * 83492791) ^ (seed * 2654435761)
    h = (h * 2654435761 + 1013904223) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 2246822519) & 0xFFFFFFFF
    return (h >> 8).astype(np.float64) / float(1 << 24)


def _frac(x: np.ndarray) -> np.ndarray:
    """Fractional part in [0, 1), the phase of every periodic pattern."""
    return x - np.floor(x)


def ground_albedo(world: World, points: np.ndarray,
                  raw: np.ndarray) -> np.ndarray:
    """Albedo of ground hits: asphalt with lane markings and zebra
    crossings, tiled sidewalks, brick paving, grass.

    Args:
        world (World): The scene.
        points (np.ndarray): Global hit points on the ground. Shape (R, 3).
        raw (np.ndarray): Raw class of every hit. Shape (R,).

    Returns:
        np.ndarray: RGB albedo. Shape (R, 3).
    """
    layout = world.layout
    u, v = layout.to_road(points[:, :2])
    albedo = np.zeros((len(points), 3))
    for raw_class, colour in _GROUND_COLOURS.items():
        albedo[raw == raw_class] = colour
    grain = 0.85 + 0.3 * value_noise(points, 0.25, 1)
    albedo *= grain[:, None]
    road = raw == RAW_DRIVEABLE
    on_street = road & (np.abs(v) < layout.road_half_width)
    centre = on_street & (np.abs(v) < 0.1) & ~layout.in_cross_street(u)
    albedo[centre] = (0.80, 0.68, 0.20)
    dashes = (on_street & (np.abs(np.abs(v) - 3.25) < 0.07)
              & (_frac(u / 6.0) < 0.5) & ~layout.in_cross_street(u))
    albedo[dashes] = _WHITE
    edge = (on_street & (np.abs(np.abs(v) - 6.2) < 0.07)
            & ~layout.in_cross_street(u))
    albedo[edge] = _WHITE
    zebra = (on_street & layout.in_cross_street(u, 3.0)
             & ~layout.in_cross_street(u) & (_frac(v / 1.0) < 0.5))
    albedo[zebra] = _WHITE
    sidewalk = raw == RAW_SIDEWALK
    joints = sidewalk & ((_frac(u / 1.2) < 0.05) | (_frac(v / 1.2) < 0.05))
    albedo[joints] *= 0.7
    flat = raw == RAW_OTHER_FLAT
    row = np.floor(v / 0.3)
    mortar = flat & ((_frac((u + 0.3 * (row % 2)) / 0.6) < 0.1)
                     | (_frac(v / 0.3) < 0.12))
    albedo[mortar] *= 0.6
    grass = raw == RAW_TERRAIN
    albedo[grass] *= (0.7 + 0.5 * value_noise(points[grass], 0.8, 2))[:, None]
    return albedo


def box_albedo(world: World, points: np.ndarray, box: np.ndarray,
               normal: np.ndarray, t: float) -> np.ndarray:
    """Albedo of box hits with a per-class pattern in the box's frame.

    Args:
        world (World): The scene.
        points (np.ndarray): Global hit points. Shape (R, 3).
        box (np.ndarray): Box index of every hit. Shape (R,).
        normal (np.ndarray): Global surface normals. Shape (R, 3).
        t (float): Seconds since the scene's first sweep.

    Returns:
        np.ndarray: RGB albedo. Shape (R, 3).
    """
    boxes = world.boxes
    local = boxes.to_local(points, box, t)
    size = boxes.size[box]
    raw = boxes.raw_class[box]
    albedo = boxes.colour[box].astype(np.float64).copy()
    height = np.clip((local[:, 2] + size[:, 2] / 2) / size[:, 2], 0, 1)
    c, s = np.cos(boxes.yaw[box]), np.sin(boxes.yaw[box])
    # Coordinate along the hit face, horizontally.
    facing_x = np.abs(c * normal[:, 0] + s * normal[:, 1]) > 0.5
    along = np.where(facing_x, local[:, 1], local[:, 0])
    vertical = np.abs(normal[:, 2]) < 0.5
    z = local[:, 2] + size[:, 2] / 2

    def paint(mask, colour):
        albedo[mask] = colour

    car = raw == 17
    paint(car & vertical & (height > 0.55) & (height < 0.92), _GLASS)
    paint(car & (height < 0.22), _DARK)
    truck = raw == 23
    cab = truck & (local[:, 0] > size[:, 0] / 2 - 1.8)
    paint(cab & vertical & (height > 0.6) & (height < 0.85), _GLASS)
    albedo[truck & ~cab & (_frac(along / 0.6) < 0.15)] *= 0.7
    bus = raw == 16
    paint(bus & vertical & (height > 0.45) & (height < 0.85), _GLASS)
    paint(bus & (height > 0.36) & (height < 0.42), _WHITE)
    construction = raw == 18
    paint(construction & (height < 0.35) & (_frac((along + z) / 0.8) < 0.5),
          _DARK)
    albedo[(raw == 22) & (_frac(z / 0.4) < 0.12)] *= 0.65
    cycle = (raw == 21) | (raw == 14)
    paint(cycle & (height < 0.5) & (_frac(along / 0.25) < 0.35), _DARK)
    pedestrian = raw == 2
    paint(pedestrian & (height > 0.87), _SKIN)
    paint(pedestrian & (height < 0.45), (0.12, 0.12, 0.20))
    cone = raw == 12
    paint(cone & (height > 0.45) & (height < 0.65), _WHITE)
    paint(cone & (height < 0.06), _DARK)
    barrier = raw == 9
    paint(barrier & (_frac((along + z) / 0.6) >= 0.5), _WHITE)
    albedo[(raw == 29) & (_frac(z / 0.15) < 0.4)] *= 0.6
    building = raw == 28
    paint(building & ~vertical, (0.40, 0.40, 0.42))
    paint(building & windows_mask(along, z) & vertical, _GLASS)
    foliage = raw == 30
    albedo[foliage] *= (0.55 + 0.7 * value_noise(points[foliage], 0.35,
                                                 3))[:, None]
    return albedo


def windows_mask(along: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Window grid on building facades (3.0 m bays, 3.2 m storeys).

    Args:
        along (np.ndarray): Horizontal coordinate along the facade.
            Shape (R,).
        z (np.ndarray): Height above the building's base. Shape (R,).

    Returns:
        np.ndarray: Whether each point lies on a window. Shape (R,).
    """
    bay, storey = _frac(along / 3.0), _frac(z / 3.2)
    return (bay > 0.3) & (bay < 0.75) & (storey > 0.35) & (storey < 0.8) & (
        z > 1.0)


def sky_colour(world: World, dirs: np.ndarray) -> np.ndarray:
    """Sky radiance towards given directions (brighter near the horizon).

    Args:
        world (World): The scene (its weather and time of day).
        dirs (np.ndarray): Global ray directions. Shape (R, 3).

    Returns:
        np.ndarray: RGB. Shape (R, 3).
    """
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    up = np.clip(unit[:, 2], 0, 1)[:, None]
    if world.is_night:
        horizon, zenith = (0.012, 0.012, 0.02), (0.002, 0.002, 0.006)
    elif world.is_rainy:
        horizon, zenith = (0.62, 0.63, 0.66), (0.45, 0.47, 0.50)
    else:
        horizon, zenith = (0.80, 0.86, 0.93), (0.35, 0.55, 0.85)
    return (1 - up) * np.asarray(horizon) + up * np.asarray(zenith)


def lighting(world: World, points: np.ndarray, normal: np.ndarray,
             ego_pose: np.ndarray) -> np.ndarray:
    """Irradiance at hit points (multiplies the albedo).

    Args:
        world (World): The scene.
        points (np.ndarray): Global hit points. Shape (R, 3).
        normal (np.ndarray): Unit normals. Shape (R, 3).
        ego_pose (np.ndarray): Ego -> global at the frame's time.
            Shape (4, 4).

    Returns:
        np.ndarray: Irradiance per point. Shape (R,).
    """
    if not world.is_night:
        sun = np.clip(normal @ world.sun_direction, 0, None)
        if world.is_rainy:
            return 0.5 + 0.3 * sun
        return 0.45 + 0.75 * sun
    light = np.full(len(points), 0.008)
    # Two headlights, 0.7 m high at the ego's front, pointing forward.
    forward = ego_pose[:3, 0]
    for side in (-0.7, 0.7):
        source = ego_pose[:3, :3] @ np.array([3.6, side, 0.7]) + ego_pose[:3,
                                                                          3]
        light += _point_light(points, normal, source, 3.0, 8.0, forward)
    # Street lamps every 30 m along both kerbs, 6 m high.
    u, _ = world.layout.to_road(points[:, :2])
    lamp_u = np.round(u / 30.0) * 30.0
    for side in (-1, 1):
        lamp = world.layout.to_global(lamp_u, np.full_like(
            lamp_u, side * world.layout.road_half_width))
        source = np.concatenate([lamp, np.full((len(u), 1), 6.0)], axis=1)
        light += _point_light(points, normal, source, 0.35, 8.0)
    return light


def _point_light(points, normal, source, power, falloff, axis=None):
    """Lambertian irradiance of a point light with ``1 / (1 + (d / f)^2)``
    falloff, optionally a forward beam ``cos^6`` around ``axis``."""
    to_light = source - points
    dist = np.linalg.norm(to_light, axis=1) + 1e-6
    cos_surface = np.clip(np.sum(normal * to_light, axis=1) / dist, 0, 1)
    irradiance = power * cos_surface / (1 + (dist / falloff) ** 2)
    if axis is not None:
        beam = np.clip(-(to_light @ axis) / dist, 0, 1) ** 6
        irradiance *= beam
    return irradiance


def shade(world: World, hits: RayHits, origin: np.ndarray, dirs: np.ndarray,
          raw: np.ndarray, ego_pose: np.ndarray, t: float) -> np.ndarray:
    """Linear RGB radiance of every ray: albedo x lighting, fogged
    towards the sky with distance; sky where nothing was hit.

    Args:
        world (World): The scene.
        hits (RayHits): Ray hits. ``R`` rays.
        origin (np.ndarray): Ray origin, global. Shape (3,).
        dirs (np.ndarray): Global ray directions. Shape (R, 3).
        raw (np.ndarray): Raw class of every hit. Shape (R,).
        ego_pose (np.ndarray): Ego -> global. Shape (4, 4).
        t (float): Seconds since the scene's first sweep.

    Returns:
        np.ndarray: RGB in about [0, 1]. Shape (R, 3).
    """
    colour = sky_colour(world, dirs)
    points = hits.points(origin, dirs)
    on_ground = hits.target == TARGET_GROUND
    on_box = hits.target >= 0
    albedo = np.zeros((len(dirs), 3))
    albedo[on_ground] = ground_albedo(world, points[on_ground],
                                      raw[on_ground])
    albedo[on_box] = box_albedo(world, points[on_box], hits.target[on_box],
                                hits.normal[on_box], t)
    hit = on_ground | on_box
    radiance = albedo[hit] * lighting(world, points[hit], hits.normal[hit],
                                      ego_pose)[:, None]
    if world.is_night:
        # Some windows are lit from inside.
        box = hits.target[hit]
        building = (box >= 0) & (world.boxes.raw_class[np.maximum(box, 0)]
                                 == 28)
        glow = building & (np.abs(albedo[hit] - _GLASS).sum(axis=1) < 1e-6)
        lit = glow & (value_noise(points[hit], 3.0, 4) < 0.4)
        radiance[lit] = 0.3 * _WINDOW_LIGHT
    distance = hits.t[hit] * np.linalg.norm(dirs[hit], axis=1)
    fog_distance = 90.0 if world.is_rainy else 250.0
    fog = (1 - np.exp(-distance / fog_distance))[:, None]
    colour[hit] = radiance * (1 - fog) + colour[hit] * fog
    return colour
