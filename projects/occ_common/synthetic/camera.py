"""The camera rigs and the ray-cast renderer.

The default rig copies nuScenes' mounting: six cameras around the roof at
yaws 0, -55, 55, 180, 110 and -110 degrees (CAM_FRONT, CAM_FRONT_RIGHT,
CAM_FRONT_LEFT, CAM_BACK, CAM_BACK_LEFT, CAM_BACK_RIGHT), with nuScenes'
1600x900 intrinsics (focal length ~1266 px, ~809 px for the wider CAM_BACK)
scaled to the requested image size. The ``'quad'`` rig stands for a robot
or a car with four wide cameras (CAM_FRONT, CAM_LEFT, CAM_BACK, CAM_RIGHT
at yaws 0, 90, 180 and -90 degrees, 100 degrees of horizontal field of view
each, so that neighbours overlap by 10 degrees), to exercise rigs other
than nuScenes'. Camera frames follow OpenCV / nuScenes:
x right, y down, z forward. Pixel ``(u, v)`` covers ``[u, u + 1) x [v, v +
1)`` in image coordinates and its ray passes through its centre ``(u + 0.5,
v + 0.5)``, so a point lands on pixel ``floor(K @ p / z)``; this is the
convention under which resizing an image by ``s`` scales K by ``s``
exactly (as image augmentation and :meth:`Camera.scaled` do).

Rendering casts one ray per pixel through :func:`.raycast.cast_rays`; each
box is only tested against the pixels its near-plane-clipped projection
covers.
"""
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import cv2
import numpy as np

from .geometry import invert_transform, make_transform, rot_x, rot_y, rot_z
from .raycast import TARGET_GROUND, cast_rays
from .textures import shade
from .world import World

CAMERA_NAMES: Tuple[str, ...] = ('CAM_FRONT', 'CAM_FRONT_RIGHT',
                                 'CAM_FRONT_LEFT', 'CAM_BACK',
                                 'CAM_BACK_LEFT', 'CAM_BACK_RIGHT')
#: The four cameras of the ``'quad'`` rig, in the order they are written.
QUAD_CAMERA_NAMES: Tuple[str, ...] = ('CAM_FRONT', 'CAM_LEFT', 'CAM_BACK',
                                      'CAM_RIGHT')

# name: (translation in the ego frame, yaw deg, fx, cx, cy at 1600x900),
# close to nuScenes' calibration of vehicle n015.
_MOUNTS: Dict[str, tuple] = {
    'CAM_FRONT': ((1.700, 0.016, 1.511), 0.0, 1266.4, 816.3, 491.5),
    'CAM_FRONT_RIGHT': ((1.551, -0.493, 1.496), -55.0, 1260.8, 808.0,
                        495.3),
    'CAM_FRONT_LEFT': ((1.522, 0.495, 1.509), 55.0, 1272.6, 826.6, 479.8),
    'CAM_BACK': ((0.028, 0.003, 1.579), 180.0, 809.2, 829.2, 481.8),
    'CAM_BACK_LEFT': ((1.036, 0.484, 1.591), 110.0, 1256.7, 817.8, 452.0),
    'CAM_BACK_RIGHT': ((1.015, -0.480, 1.562), -110.0, 1259.5, 807.3,
                       501.2),
}
# The 'quad' rig: 100 degrees horizontal field of view at 1600x900 (fx =
# 800 / tan(50 deg)), square pixels, the principal point at the centre; the
# cameras sit at the roof's edges of a 1.6 m wide car.
_QUAD_FOCAL = 800.0 / np.tan(np.deg2rad(50.0))
_QUAD_MOUNTS: Dict[str, tuple] = {
    'CAM_FRONT': ((1.60, 0.00, 1.55), 0.0, _QUAD_FOCAL, 800.0, 450.0),
    'CAM_LEFT': ((0.90, 0.80, 1.60), 90.0, _QUAD_FOCAL, 800.0, 450.0),
    'CAM_BACK': ((-0.20, 0.00, 1.60), 180.0, _QUAD_FOCAL, 800.0, 450.0),
    'CAM_RIGHT': ((0.90, -0.80, 1.60), -90.0, _QUAD_FOCAL, 800.0, 450.0),
}
#: Camera rigs by name: their cameras in order and their mounts.
CAMERA_RIGS: Dict[str, Tuple[Tuple[str, ...], Dict[str, tuple]]] = {
    'nuscenes': (CAMERA_NAMES, _MOUNTS),
    'quad': (QUAD_CAMERA_NAMES, _QUAD_MOUNTS),
}
#: Optical axis -> ego axes for a camera looking along ego +x:
#: camera x (right) = ego -y, camera y (down) = ego -z, camera z = ego +x.
_CAM_TO_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0],
                            [0.0, -1.0, 0.0]])
_NEAR = 0.1
_FAR = 250.0


@dataclass
class Camera:
    """One calibrated camera.

    Args:
        name (str): nuScenes channel, e.g. ``CAM_FRONT``.
        intrinsic (np.ndarray): Pinhole matrix K. Shape (3, 3).
        cam2ego (np.ndarray): Camera -> ego transform. Shape (4, 4).
        width (int): Image width in pixels.
        height (int): Image height in pixels.
    """
    name: str
    intrinsic: np.ndarray
    cam2ego: np.ndarray
    width: int
    height: int

    def scaled(self, width: int, height: int) -> 'Camera':
        """The same camera with an image of another size (same field of
        view).

        Args:
            width (int): New width.
            height (int): New height.

        Returns:
            Camera: The rescaled camera.
        """
        scale = np.diag([width / self.width, height / self.height, 1.0])
        return Camera(self.name, scale @ self.intrinsic, self.cam2ego, width,
                      height)

    def pixel_rays(self) -> np.ndarray:
        """Camera-frame rays through every pixel centre ``(u + 0.5, v +
        0.5)``, with z = 1 (so the ray parameter of a hit is its depth).

        Returns:
            np.ndarray: Directions, row-major. Shape (H * W, 3).
        """
        v, u = np.mgrid[0:self.height, 0:self.width] + 0.5
        k = self.intrinsic
        x = (u - k[0, 2]) / k[0, 0]
        y = (v - k[1, 2]) / k[1, 1]
        return np.stack([x, y, np.ones_like(x)], axis=-1).reshape(-1, 3)


def make_camera_rig(image_size: Tuple[int, int],
                    rng: Optional[np.random.Generator] = None,
                    rig: str = 'nuscenes') -> List[Camera]:
    """The cameras of a rig for an image size.

    Args:
        image_size (Tuple[int, int]): ``(width, height)`` in pixels.
        rng (np.random.Generator, optional): Adds a per-rig calibration
            jitter (+-1 cm, +-0.3 deg), as real rigs differ between logs.
            Defaults to None (no jitter).
        rig (str): A key of :data:`CAMERA_RIGS`: ``'nuscenes'`` (six
            cameras) or ``'quad'`` (four). Defaults to 'nuscenes'.

    Returns:
        List[Camera]: Cameras in the rig's order (:data:`CAMERA_NAMES` for
        nuScenes', :data:`QUAD_CAMERA_NAMES` for the quad rig).

    Raises:
        ValueError: If ``rig`` is not a known rig.
    """
    if rig not in CAMERA_RIGS:
        raise ValueError(f'Expected rig to be one of {sorted(CAMERA_RIGS)}, '
                         f'got {rig!r}.')
    names, mounts = CAMERA_RIGS[rig]
    width, height = image_size
    cameras = []
    for index, name in enumerate(names):
        translation, yaw, focal, cx, cy = mounts[name]
        # A small fixed tilt, as real mounts have, makes every camera's
        # rotation a full 3D one.
        pitch = np.deg2rad(0.4 * ((index % 3) - 1))
        roll = np.deg2rad(0.3 * ((index % 2) * 2 - 1))
        translation = np.asarray(translation, dtype=np.float64)
        if rng is not None:
            translation = translation + rng.uniform(-0.01, 0.01, 3)
            yaw += rng.uniform(-0.3, 0.3)
            pitch += np.deg2rad(rng.uniform(-0.3, 0.3))
        rotation = rot_z(np.deg2rad(yaw)) @ rot_y(pitch) @ rot_x(
            roll) @ _CAM_TO_FORWARD
        sx, sy = width / 1600.0, height / 900.0
        intrinsic = np.array([[focal * sx, 0.0, cx * sx],
                              [0.0, focal * sy, cy * sy], [0.0, 0.0, 1.0]])
        cameras.append(Camera(name, intrinsic,
                              make_transform(rotation, translation), width,
                              height))
    return cameras


_EDGES = np.array([(i, i ^ bit) for i in range(8) for bit in (1, 2, 4)
                   if not i & bit])


def box_pixel_candidates(camera: Camera, cam2world: np.ndarray,
                         corners: np.ndarray) -> list:
    """Pixels each box may cover: the bounding rectangle of its projection
    after clipping the box at the near plane.

    Args:
        camera (Camera): The camera.
        cam2world (np.ndarray): Camera -> global. Shape (4, 4).
        corners (np.ndarray): Box corners, global (in the bit order of
            :meth:`.world.Boxes.corners_at`). Shape (N, 8, 3).

    Returns:
        list: Per box, an int64 array of row-major pixel indices (empty
        when the box is out of view).
    """
    world2cam = invert_transform(cam2world)
    cam = corners @ world2cam[:3, :3].T + world2cam[:3, 3]
    start, end = cam[:, _EDGES[:, 0]], cam[:, _EDGES[:, 1]]
    # Where an edge crosses the near plane, its crossing point bounds the
    # clipped projection too.
    dz = end[..., 2] - start[..., 2]
    crosses = (start[..., 2] - _NEAR) * (end[..., 2] - _NEAR) < 0
    ratio = np.where(crosses, (_NEAR - start[..., 2]) / np.where(
        dz == 0, 1.0, dz), 0.0)
    crossing = start + ratio[..., None] * (end - start)
    points = np.concatenate([cam, crossing], axis=1)
    valid = np.concatenate([cam[..., 2] >= _NEAR, crosses], axis=1)
    k = camera.intrinsic
    z = np.maximum(points[..., 2], _NEAR)
    u = k[0, 0] * points[..., 0] / z + k[0, 2]
    v = k[1, 1] * points[..., 1] / z + k[1, 2]
    result = []
    for box in range(len(corners)):
        ok = valid[box]
        if not ok.any():
            result.append(np.zeros(0, dtype=np.int64))
            continue
        u0 = max(int(np.floor(u[box, ok].min())), 0)
        u1 = min(int(np.ceil(u[box, ok].max())), camera.width - 1)
        v0 = max(int(np.floor(v[box, ok].min())), 0)
        v1 = min(int(np.ceil(v[box, ok].max())), camera.height - 1)
        if u0 > u1 or v0 > v1:
            result.append(np.zeros(0, dtype=np.int64))
            continue
        rows, cols = np.arange(v0, v1 + 1), np.arange(u0, u1 + 1)
        result.append((rows[:, None] * camera.width + cols[None]).ravel())
    return result


def render_camera(world: World, camera: Camera, ego_pose: np.ndarray,
                  t: float) -> Dict[str, np.ndarray]:
    """Renders one camera image of a world by ray casting.

    Args:
        world (World): The scene.
        camera (Camera): The camera.
        ego_pose (np.ndarray): Ego -> global at the frame. Shape (4, 4).
        t (float): Seconds since the scene's first sweep (moving objects'
            positions).

    Returns:
        Dict[str, np.ndarray]: ``radiance`` float RGB (H, W, 3) before
        sensor effects; ``raw_class`` uint8 (H, W), the raw lidarseg class
        seen at every pixel (0 for sky); ``depth`` float32 (H, W), 0 for
        sky; ``box_visible`` (N,) and ``box_projected`` (N,) pixel counts
        of every box with and without occlusion.
    """
    cam2world = ego_pose @ camera.cam2ego
    origin = cam2world[:3, 3]
    dirs = camera.pixel_rays() @ cam2world[:3, :3].T
    boxes = world.boxes
    corners = boxes.corners_at(t)
    candidates = box_pixel_candidates(camera, cam2world, corners)
    hits = cast_rays(origin, dirs, boxes.centers_at(t), boxes.size,
                     boxes.yaw, candidates, t_min=_NEAR, t_max=_FAR)
    raw = np.zeros(len(dirs), dtype=np.uint8)
    on_box = hits.target >= 0
    raw[on_box] = boxes.raw_class[hits.target[on_box]]
    on_ground = hits.target == TARGET_GROUND
    points = hits.points(origin, dirs)
    raw[on_ground] = world.ground_class(points[on_ground, :2])
    radiance = shade(world, hits, origin, dirs, raw, ego_pose, t)
    shape = (camera.height, camera.width)
    depth = np.where(np.isfinite(hits.t), hits.t, 0.0).astype(np.float32)
    visible = np.bincount(hits.target[on_box], minlength=len(boxes))
    return dict(radiance=radiance.reshape(shape + (3, )),
                raw_class=raw.reshape(shape), depth=depth.reshape(shape),
                box_visible=visible, box_projected=hits.box_ray_counts)


def finish_image(radiance: np.ndarray, world: World,
                 rng: np.random.Generator) -> np.ndarray:
    """Sensor effects: rain streaks, exposure, noise, 8-bit quantisation.

    Args:
        radiance (np.ndarray): Linear RGB. Shape (H, W, 3).
        world (World): The scene (rain / night).
        rng (np.random.Generator): Noise and streak positions.

    Returns:
        np.ndarray: RGB image, uint8. Shape (H, W, 3).
    """
    image = radiance.astype(np.float32)
    height, width = image.shape[:2]
    if world.is_rainy:
        # Lower contrast under a veil and slanted streaks, both as bright as
        # the (day or night) sky.
        sky = 0.012 if world.is_night else 0.62
        image = 0.75 * image + 0.12 * sky
        streaks = np.zeros((height, width), dtype=np.float32)
        length = max(3, height // 12)
        for _ in range(max(1, height * width // 500)):
            x, y = int(rng.integers(width)), int(rng.integers(height))
            cv2.line(streaks, (x, y), (x + length // 4, y + length), 1.0, 1)
        alpha = 0.3 * streaks[..., None]
        image = image * (1 - alpha) + alpha * 1.3 * sky
    noise = 0.004 if world.is_night else 0.01
    image = image + rng.normal(0, noise, image.shape).astype(np.float32)
    # Gamma 2.2 so that dark scenes stay dark in the 8-bit image.
    image = np.clip(image, 0, 1) ** (1 / 2.2)
    return (image * 255 + 0.5).astype(np.uint8)
