"""3D perspective view of an occupancy grid: a painter's-algorithm renderer.

matplotlib's ``Axes3D.voxels`` builds one artist per face and needs minutes
for a 200x200x16 grid; here the geometry is vectorised in numpy and only
the polygon fill is left to Pillow:

1. keep the faces of drawn voxels whose neighbour across the face is not
   drawn (the surface) and that face the camera (back-face culling);
2. project their corners with a pinhole camera looking at the grid centre;
3. paint them far to near (painter's algorithm), each shaded by its normal
   so that tops, sides and fronts of a block read apart.

Ordering by the distance of the face centres from the eye suits a grid:
its faces are equal and never intersect, so a wrong overlap needs a
grazing view of two faces of very different depth, which the default
elevation avoids.
The grid is centred at the origin, z up; the camera's azimuth is measured
from the grid direction ahead of the car (``forward``, :mod:`.orientation`),
so a view from behind the car is a view from behind in the ego frame
(Occ3D) and in nuScenes' LiDAR frame (SurroundOcc) alike, and a top-down
view puts ahead of the car up.
"""
import math
from typing import Optional, Sequence, Tuple

import numpy as np
from PIL import Image, ImageDraw

from .label_grid import occupied_voxels
from .orientation import FORWARD_HEADINGS, check_forward
from .palette import BACKGROUND

#: Brightness of a face by its normal ``(axis, sign)``: lit from above and
#: slightly from the front-left.
FACE_SHADES = {
    (2, 1): 1.0,
    (2, -1): 0.5,
    (0, 1): 0.85,
    (0, -1): 0.8,
    (1, 1): 0.7,
    (1, -1): 0.65,
}

#: Corner order of a face in its two in-plane axes, walking round it.
_QUAD = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)


def look_at(extent: np.ndarray,
            azimuth: float,
            elevation: float,
            fov: float,
            forward: str = '+x') -> Tuple[np.ndarray, np.ndarray, float]:
    """A camera on a sphere round the grid, looking at its centre.

    Args:
        extent (np.ndarray): Grid size in metres (x, y, z). Shape (3,).
        azimuth (float): Direction of the camera from the centre in
            degrees, counter-clockwise from ``forward`` (180 = behind the
            ego).
        elevation (float): Degrees above the xy plane (90 = top-down).
        fov (float): Field of view in degrees: the perspective strength.
        forward (str): Grid direction ahead of the car. Defaults to '+x'.

    Returns:
        tuple: ``eye`` Shape (3,), ``axes`` Shape (3, 3) whose rows are
        the camera's right, up and forward unit vectors, and the distance
        from the eye to the centre.
    """
    heading = math.radians(FORWARD_HEADINGS[check_forward(forward)])
    az, el = math.radians(azimuth) + heading, math.radians(elevation)
    direction = np.array([
        math.cos(el) * math.cos(az),
        math.cos(el) * math.sin(az),
        math.sin(el)
    ])
    # The bounding sphere fits in the field of view at this distance.
    radius = 0.5 * float(np.linalg.norm(extent))
    distance = 1.05 * radius / math.sin(math.radians(fov) / 2)
    eye = distance * direction
    view = -direction
    right = np.cross(view, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-6:
        # Looking straight down: keep ahead of the car up the image.
        right = np.cross(view,
                         [math.cos(heading), math.sin(heading), 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, view)
    return eye, np.stack([right, up, view]), distance


def surface_faces(drawn: np.ndarray, voxel_size: np.ndarray,
                  eye: np.ndarray) -> Tuple[np.ndarray, np.ndarray,
                                            np.ndarray, np.ndarray]:
    """Visible surface faces of the drawn voxels.

    Args:
        drawn (np.ndarray): Shape (X, Y, Z), bool.
        voxel_size (np.ndarray): Metres per voxel (x, y, z). Shape (3,).
        eye (np.ndarray): Camera position in the centred grid frame.
            Shape (3,).

    Returns:
        tuple: ``corners`` Shape (F, 4, 3), ``centres`` Shape (F, 3),
        ``voxel`` index of each face's voxel Shape (F, 3), and ``shade``
        Shape (F,).
    """
    shape = np.asarray(drawn.shape)
    index = np.argwhere(drawn)
    centre = (index + 0.5) * voxel_size - shape * voxel_size / 2
    padded = np.pad(drawn, 1)
    corners, centres, voxels, shades = [], [], [], []
    for axis in range(3):
        u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
        for sign in (1, -1):
            neighbour = index + 1
            neighbour[:, axis] += sign
            exposed = ~padded[tuple(neighbour.T)]
            face_centre = centre.copy()
            face_centre[:, axis] += sign * voxel_size[axis] / 2
            # Back-face culling: the outward normal points at the eye.
            facing = sign * (eye[axis] - face_centre[:, axis]) > 0
            keep = exposed & facing
            quad = np.repeat(face_centre[keep][:, None], 4, axis=1)
            quad[..., u_axis] += _QUAD[:, 0] * voxel_size[u_axis] / 2
            quad[..., v_axis] += _QUAD[:, 1] * voxel_size[v_axis] / 2
            corners.append(quad)
            centres.append(face_centre[keep])
            voxels.append(index[keep])
            shades.append(
                np.full(int(keep.sum()), FACE_SHADES[(axis, sign)]))
    return (np.concatenate(corners), np.concatenate(centres),
            np.concatenate(voxels), np.concatenate(shades))


def project_to_frame(points: np.ndarray, eye: np.ndarray, axes: np.ndarray,
                     extent: np.ndarray, image_size: Tuple[int, int],
                     margin: float = 0.04) -> np.ndarray:
    """Project points so that the whole grid box fills the image.

    The framing depends on the grid box only, never on what is drawn, so
    the prediction, GT and error views of one grid line up pixel for pixel.

    Args:
        points (np.ndarray): Shape (..., 3), centred grid frame.
        eye (np.ndarray): Shape (3,).
        axes (np.ndarray): Camera right, up, forward rows. Shape (3, 3).
        extent (np.ndarray): Grid size (x, y, z). Shape (3,).
        image_size (tuple[int, int]): ``(H, W)``.
        margin (float): Border left free, as a fraction of each side.
            Defaults to 0.04.

    Returns:
        np.ndarray: Pixel coordinates (column, row). Shape (..., 2).
    """
    height, width = image_size

    def normalised(xyz):
        cam = (xyz - eye) @ axes.T
        return np.stack([cam[..., 0] / cam[..., 2],
                         -cam[..., 1] / cam[..., 2]], axis=-1)

    box = np.stack(np.meshgrid([-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5],
                               indexing='ij'), axis=-1).reshape(-1, 3)
    box_uv = normalised(box * extent)
    low, high = box_uv.min(axis=0), box_uv.max(axis=0)
    # One scale for both axes keeps the perspective undistorted.
    scale = min(width * (1 - 2 * margin) / (high[0] - low[0]),
                height * (1 - 2 * margin) / (high[1] - low[1]))
    offset = np.array([width, height]) / 2 - scale * (low + high) / 2
    return normalised(points) * scale + offset


def render_voxels(labels: np.ndarray,
                  palette: np.ndarray,
                  empty_label: int,
                  ignore_index: int = 255,
                  mask: Optional[np.ndarray] = None,
                  voxel_size: Sequence[float] = (1.0, 1.0, 1.0),
                  image_size: Sequence[int] = (480, 640),
                  azimuth: float = -150.0,
                  elevation: float = 40.0,
                  fov: float = 40.0,
                  edge_shade: Optional[float] = 0.75,
                  background: Sequence[int] = BACKGROUND,
                  name: str = 'occupancy',
                  forward: str = '+x') -> np.ndarray:
    """Render the 3D perspective view.

    Args:
        labels (np.ndarray): Shape (X, Y, Z), int.
        palette (np.ndarray): Shape (C, 3), uint8.
        empty_label (int): Label of empty space, not drawn.
        ignore_index (int): Label not drawn. Defaults to 255.
        mask (np.ndarray, optional): Voxels to draw, Shape (X, Y, Z).
            Defaults to None (all).
        voxel_size (Sequence[float]): Metres per voxel (x, y, z), for the
            proportions. Defaults to cubes.
        image_size (Sequence[int]): ``(H, W)``. Defaults to (480, 640).
        azimuth (float): See :func:`look_at`. Defaults to -150 (behind
            the ego, to its right).
        elevation (float): See :func:`look_at`. Defaults to 40.
        fov (float): Field of view in degrees. Defaults to 40.
        edge_shade (float, optional): Face outlines are the face colour
            times this; None draws no outlines. Defaults to 0.75.
        background (Sequence[int]): RGB where no voxel is seen. Defaults
            to white.
        name (str): Named in errors. Defaults to 'occupancy'.
        forward (str): Grid direction ahead of the car, the origin of
            ``azimuth`` (see :mod:`.orientation`). Defaults to '+x'.

    Returns:
        np.ndarray: Shape (H, W, 3), uint8.
    """
    height, width = (int(v) for v in image_size)
    image = Image.new('RGB', (width, height), tuple(int(v)
                                                    for v in background))
    drawn = occupied_voxels(labels, len(palette), empty_label, ignore_index,
                            mask, name)
    if not drawn.any():
        return np.asarray(image).copy()
    size = np.asarray(voxel_size, dtype=np.float64)
    eye, axes, _ = look_at(
        np.asarray(labels.shape) * size, azimuth, elevation, fov, forward)
    corners, centres, voxels, shade = surface_faces(drawn, size, eye)

    pixels = project_to_frame(corners, eye, axes,
                              np.asarray(labels.shape) * size,
                              (height, width))

    colour = palette[labels[tuple(voxels.T)]] * shade[:, None]
    fill = np.rint(colour).astype(np.uint8)
    far_first = np.argsort(-np.linalg.norm(centres - eye, axis=1),
                           kind='stable')
    painter = ImageDraw.Draw(image)
    fills = [tuple(c) for c in fill[far_first].tolist()]
    polygons = pixels[far_first].reshape(-1, 8).tolist()
    if edge_shade is None:
        for polygon, face_fill in zip(polygons, fills):
            painter.polygon(polygon, fill=face_fill)
    else:
        edges = np.rint(colour[far_first] * edge_shade).astype(np.uint8)
        for polygon, face_fill, edge in zip(polygons, fills,
                                            edges.tolist()):
            painter.polygon(polygon, fill=face_fill, outline=tuple(edge))
    return np.asarray(image).copy()
