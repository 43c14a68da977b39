"""The 3D world of one synthetic scene: ground layout, objects, ego motion.

Every sensor of a scene (the cameras, the LiDAR) and both occupancy ground
truths are computed from the same :class:`World`, so they agree by
construction. The world is a straight street in a "road frame" ``(u, v)``
(``u`` along the street, ``v`` to its left) placed in the global frame by an
origin and a heading:

* the ground is the plane ``z = 0`` whose class depends on ``(u, v)``:
  driveable surface (the street and its cross streets), sidewalks, terrain
  and patches of other flat ground (driveways, plazas);
* everything else is an oriented box (yaw only) with one raw
  nuScenes-lidarseg class: buildings (manmade), trees and hedges
  (vegetation), vehicles, pedestrians, cones, barriers, bicycles, ...;
  moving boxes translate with a constant velocity;
* the ego vehicle drives along the street with a gentle weave, so its yaw
  changes between sweeps.
"""
from dataclasses import dataclass, field
from typing import List, Tuple

import numpy as np

from .geometry import make_transform, rot_z

# Raw nuScenes-lidarseg indices of the ground classes (see
# nuscenes_classes.LIDARSEG_RAW_CLASS_NAMES).
RAW_DRIVEABLE = 24
RAW_OTHER_FLAT = 25
RAW_SIDEWALK = 26
RAW_TERRAIN = 27

#: Thickness of the solid ground slab ``-GROUND_THICKNESS <= z <= 0``. Thin
#: enough that it fills exactly one voxel layer of both occupancy grids.
GROUND_THICKNESS = 0.2


@dataclass
class Boxes:
    """Oriented boxes (yaw only) of one world, at time 0.

    Args:
        center (np.ndarray): Box centres in the global frame at t = 0.
            Shape (N, 3).
        size (np.ndarray): Length (along the box's heading), width, height
            in metres. Shape (N, 3).
        yaw (np.ndarray): Heading in the global frame, radians. Shape (N,).
        velocity (np.ndarray): Global xy velocity, m/s. Shape (N, 2).
        raw_class (np.ndarray): Raw nuScenes-lidarseg class, uint8.
            Shape (N,).
        colour (np.ndarray): Base RGB albedo in [0, 1]. Shape (N, 3).
        annotated (np.ndarray): Whether the box is an object that gets
            ``sample_annotation`` records (not buildings or vegetation).
            Shape (N,).
        attribute (List[str]): nuScenes attribute name per box, '' if none.
    """
    center: np.ndarray
    size: np.ndarray
    yaw: np.ndarray
    velocity: np.ndarray
    raw_class: np.ndarray
    colour: np.ndarray
    annotated: np.ndarray
    attribute: List[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.yaw)

    def centers_at(self, t: float) -> np.ndarray:
        """Box centres at time ``t`` (constant-velocity motion).

        Args:
            t (float): Seconds since the scene's first sweep.

        Returns:
            np.ndarray: Centres. Shape (N, 3).
        """
        centers = self.center.copy()
        centers[:, :2] += self.velocity * t
        return centers

    def corners_at(self, t: float) -> np.ndarray:
        """The 8 corners of every box at time ``t``.

        Args:
            t (float): Seconds since the scene's first sweep.

        Returns:
            np.ndarray: Corners in the global frame. Shape (N, 8, 3).
        """
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                          for sz in (-1, 1)], dtype=np.float64)
        local = signs[None] * self.size[:, None] / 2.0
        c, s = np.cos(self.yaw)[:, None], np.sin(self.yaw)[:, None]
        world = np.empty_like(local)
        world[..., 0] = c * local[..., 0] - s * local[..., 1]
        world[..., 1] = s * local[..., 0] + c * local[..., 1]
        world[..., 2] = local[..., 2]
        return world + self.centers_at(t)[:, None]

    def to_local(self, points: np.ndarray, index: np.ndarray,
                 t: float) -> np.ndarray:
        """Expresses points in the frame of given boxes (centre origin,
        x along the heading).

        Args:
            points (np.ndarray): Global points. Shape (M, 3).
            index (np.ndarray): Box of every point. Shape (M,).
            t (float): Seconds since the scene's first sweep.

        Returns:
            np.ndarray: Box-frame coordinates. Shape (M, 3).
        """
        delta = points - self.centers_at(t)[index]
        c, s = np.cos(self.yaw[index]), np.sin(self.yaw[index])
        return np.stack([c * delta[:, 0] + s * delta[:, 1],
                         -s * delta[:, 0] + c * delta[:, 1], delta[:, 2]],
                        axis=1)


@dataclass
class RoadLayout:
    """The ground of a world: a straight street with cross streets.

    Args:
        origin (np.ndarray): Global xy of the road frame's origin.
            Shape (2,).
        heading (float): Global yaw of the road frame's +u axis.
        road_half_width (float): Half width of the driveable street, m.
        sidewalk_width (float): Width of the sidewalk on each side, m.
        cross_streets (np.ndarray): ``u`` of every cross street's centre
            line. Shape (K,).
        cross_half_width (float): Half width of the cross streets, m.
        flat_patches (np.ndarray): Rectangles ``u0, u1, v0, v1`` of other
            flat ground inside the terrain. Shape (P, 4).
    """
    origin: np.ndarray
    heading: float
    road_half_width: float = 8.5
    sidewalk_width: float = 3.5
    cross_streets: np.ndarray = field(
        default_factory=lambda: np.zeros(0))
    cross_half_width: float = 6.0
    flat_patches: np.ndarray = field(
        default_factory=lambda: np.zeros((0, 4)))

    def to_road(self, xy: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Global xy -> road frame ``(u, v)``.

        Args:
            xy (np.ndarray): Global coordinates. Shape (..., 2).

        Returns:
            Tuple[np.ndarray, np.ndarray]: ``u`` and ``v``, each of shape
            (...).
        """
        c, s = np.cos(self.heading), np.sin(self.heading)
        dx = xy[..., 0] - self.origin[0]
        dy = xy[..., 1] - self.origin[1]
        return c * dx + s * dy, -s * dx + c * dy

    def to_global(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Road frame ``(u, v)`` -> global xy.

        Args:
            u (np.ndarray): Along-street coordinate. Shape (...).
            v (np.ndarray): Across-street coordinate. Shape (...).

        Returns:
            np.ndarray: Global coordinates. Shape (..., 2).
        """
        c, s = np.cos(self.heading), np.sin(self.heading)
        u, v = np.asarray(u, dtype=np.float64), np.asarray(v, np.float64)
        return np.stack([self.origin[0] + c * u - s * v,
                         self.origin[1] + s * u + c * v], axis=-1)

    def in_cross_street(self, u: np.ndarray, margin: float = 0.0
                        ) -> np.ndarray:
        """Whether ``u`` lies in a cross street (widened by ``margin``).

        Args:
            u (np.ndarray): Along-street coordinate. Shape (...).
            margin (float): Extra half width, m. Defaults to 0.

        Returns:
            np.ndarray: Boolean mask. Shape (...).
        """
        inside = np.zeros(np.shape(u), dtype=bool)
        for center in self.cross_streets:
            inside |= np.abs(u - center) < self.cross_half_width + margin
        return inside

    def in_flat_patch(self, u: np.ndarray, v: np.ndarray,
                      margin: float = 0.0) -> np.ndarray:
        """Whether ``(u, v)`` lies in a patch of other flat ground.

        Args:
            u (np.ndarray): Along-street coordinate. Shape (...).
            v (np.ndarray): Across-street coordinate. Shape (...).
            margin (float): Grows every patch by this much, m.
                Defaults to 0.

        Returns:
            np.ndarray: Boolean mask. Shape (...).
        """
        inside = np.zeros(np.shape(u), dtype=bool)
        for u0, u1, v0, v1 in self.flat_patches:
            inside |= ((u >= u0 - margin) & (u <= u1 + margin)
                       & (v >= v0 - margin) & (v <= v1 + margin))
        return inside

    def ground_class(self, xy: np.ndarray) -> np.ndarray:
        """Raw nuScenes-lidarseg class of the ground at global ``xy``.

        Args:
            xy (np.ndarray): Global coordinates. Shape (..., 2).

        Returns:
            np.ndarray: Raw class (24 driveable, 25 other flat, 26 sidewalk,
            27 terrain), uint8. Shape (...).
        """
        u, v = self.to_road(xy)
        abs_v = np.abs(v)
        label = np.full(u.shape, RAW_TERRAIN, dtype=np.uint8)
        label[abs_v < self.road_half_width + self.sidewalk_width] = (
            RAW_SIDEWALK)
        label[self.in_flat_patch(u, v)] = RAW_OTHER_FLAT
        # Cross streets cut through the sidewalks and the terrain.
        driveable = (abs_v < self.road_half_width) | self.in_cross_street(u)
        label[driveable] = RAW_DRIVEABLE
        return label


@dataclass
class EgoMotion:
    """The ego vehicle's path: along the street with a lateral weave.

    ``u(t) = u0 + speed * t + accel * t^2 / 2`` and
    ``v(t) = lane_v + weave_amp * sin(weave_freq * t + weave_phase)``; the
    ego's yaw follows the path's tangent.

    Args:
        u0 (float): Start position along the street, m.
        speed (float): Initial speed, m/s.
        accel (float): Constant acceleration, m/s^2.
        lane_v (float): Lane centre across the street, m.
        weave_amp (float): Weave amplitude, m.
        weave_freq (float): Weave angular frequency, rad/s.
        weave_phase (float): Weave phase, rad.
    """
    u0: float
    speed: float
    accel: float
    lane_v: float
    weave_amp: float
    weave_freq: float
    weave_phase: float

    def road_state(self, t: float) -> Tuple[float, float, float]:
        """Road-frame position and yaw (relative to the street) at ``t``.

        Args:
            t (float): Seconds since the scene's first sweep.

        Returns:
            Tuple[float, float, float]: ``u``, ``v`` and relative yaw.
        """
        u = self.u0 + self.speed * t + 0.5 * self.accel * t * t
        phase = self.weave_freq * t + self.weave_phase
        v = self.lane_v + self.weave_amp * np.sin(phase)
        du = self.speed + self.accel * t
        dv = self.weave_amp * self.weave_freq * np.cos(phase)
        return float(u), float(v), float(np.arctan2(dv, du))


@dataclass
class World:
    """Everything one scene's sensors observe.

    Args:
        layout (RoadLayout): The ground.
        boxes (Boxes): Every object, building and plant.
        ego (EgoMotion): The ego vehicle's path.
        is_rainy (bool): Rain: darker, low-contrast images with streaks and
            spurious LiDAR returns.
        is_night (bool): Night: dark images lit by the ego's headlights and
            lit windows.
        description (str): The scene's nuScenes description.
        sun_direction (np.ndarray): Unit vector towards the sun, global
            frame. Shape (3,).
    """
    layout: RoadLayout
    boxes: Boxes
    ego: EgoMotion
    is_rainy: bool
    is_night: bool
    description: str
    sun_direction: np.ndarray

    def ground_class(self, xy: np.ndarray) -> np.ndarray:
        """Raw class of the ground at global ``xy``; see
        :meth:`RoadLayout.ground_class`."""
        return self.layout.ground_class(xy)

    def ego_pose(self, t: float) -> np.ndarray:
        """Ego -> global transform at time ``t`` (ego origin on the ground,
        x forward, y left, z up).

        Args:
            t (float): Seconds since the scene's first sweep.

        Returns:
            np.ndarray: Transform. Shape (4, 4).
        """
        u, v, rel_yaw = self.ego.road_state(t)
        xy = self.layout.to_global(u, v)
        return make_transform(
            rot_z(self.layout.heading + rel_yaw), [xy[0], xy[1], 0.0])


def world_to_dict(world: World) -> dict:
    """JSON-serialisable description of a world (see
    :func:`world_from_dict`).

    Args:
        world (World): The world.

    Returns:
        dict: Plain lists, floats and strings.
    """
    boxes, layout, ego = world.boxes, world.layout, world.ego
    return dict(
        layout=dict(origin=layout.origin.tolist(),
                    heading=float(layout.heading),
                    road_half_width=layout.road_half_width,
                    sidewalk_width=layout.sidewalk_width,
                    cross_streets=layout.cross_streets.tolist(),
                    cross_half_width=layout.cross_half_width,
                    flat_patches=layout.flat_patches.tolist()),
        boxes=dict(center=boxes.center.tolist(), size=boxes.size.tolist(),
                   yaw=boxes.yaw.tolist(), velocity=boxes.velocity.tolist(),
                   raw_class=boxes.raw_class.tolist(),
                   colour=boxes.colour.tolist(),
                   annotated=boxes.annotated.tolist(),
                   attribute=list(boxes.attribute)),
        ego={k: float(v) for k, v in vars(ego).items()},
        is_rainy=world.is_rainy, is_night=world.is_night,
        description=world.description,
        sun_direction=world.sun_direction.tolist())


def world_from_dict(data: dict) -> World:
    """Rebuilds a world written by :func:`world_to_dict`.

    Args:
        data (dict): The description.

    Returns:
        World: The world.
    """
    layout = dict(data['layout'])
    layout['origin'] = np.asarray(layout['origin'], dtype=np.float64)
    layout['cross_streets'] = np.asarray(layout['cross_streets'],
                                         dtype=np.float64)
    layout['flat_patches'] = np.asarray(layout['flat_patches'],
                                        dtype=np.float64).reshape(-1, 4)
    b = data['boxes']
    boxes = Boxes(
        center=np.asarray(b['center'], np.float64).reshape(-1, 3),
        size=np.asarray(b['size'], np.float64).reshape(-1, 3),
        yaw=np.asarray(b['yaw'], np.float64),
        velocity=np.asarray(b['velocity'], np.float64).reshape(-1, 2),
        raw_class=np.asarray(b['raw_class'], np.uint8),
        colour=np.asarray(b['colour'], np.float64).reshape(-1, 3),
        annotated=np.asarray(b['annotated'], bool),
        attribute=list(b['attribute']))
    return World(layout=RoadLayout(**layout), boxes=boxes,
                 ego=EgoMotion(**data['ego']), is_rainy=data['is_rainy'],
                 is_night=data['is_night'], description=data['description'],
                 sun_direction=np.asarray(data['sun_direction']))
