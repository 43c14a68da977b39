"""Point labels from the occupancy grid, for data without nuScenes-lidarseg.

SDG-OCC's 2-D semantic supervision projects labelled LiDAR points into the
images (:class:`.depth_maps.PointsToSemanticMaps`). The labels come from
nuScenes-lidarseg when the info file has them; many SurroundOcc / Occ3D
users never downloaded it, so the same maps can be made from the occupancy
labels instead: each key-frame point takes the label of the voxel it falls
in.

Why points and not rays cast through the voxels: a point is a surface the
sensor saw, so the maps keep lidarseg's density, depth order (nearest
point per pixel) and key-frame-only timing, and the two sources give
targets of the same kind; a voxel ray cast would paint every pixel with
0.4-0.5 m blocks whose projected edges do not follow the image, including
voxels the camera cannot see (SurroundOcc's labels are dense behind
walls), at 6 x H x W rays of ~100 steps per sample on the loader's CPU.
What a point loses: a point in a voxel labelled empty / free / others
(a voxel edge, or a class the labels merged away) is unlabelled (255),
as lidarseg's ignored classes are.
"""
import numpy as np

from ..datasets.occ_formats import IGNORE_INDEX

#: The lidarseg classes of both label formats (0 is SurroundOcc's empty and
#: Occ3D's others, 17 Occ3D's free: unlabelled, as lidarseg's ignored
#: classes are).
FIRST_CLASS, LAST_CLASS = 1, 16


def point_voxel_index(xyz: np.ndarray, grid_shape, pc_range: np.ndarray,
                      voxel_size: np.ndarray) -> tuple:
    """The voxel each point falls in, and whether it is inside the grid.

    Voxel ``(i, j, k)`` covers ``[lo + i * s, lo + (i + 1) * s)`` per axis
    (``lo`` the low corner of ``pc_range``, ``s`` the voxel size), the
    convention of the label files.

    Args:
        xyz (np.ndarray): Points in the grid's frame. Shape (P, 3).
        grid_shape (Sequence[int]): ``(X, Y, Z)``.
        pc_range (np.ndarray): ``(x0, y0, z0, x1, y1, z1)`` of the grid.
        voxel_size (np.ndarray): Shape (3,), metres.

    Returns:
        tuple[np.ndarray, np.ndarray]: Indices, int64, shape (P, 3), and
        the inside mask, bool, shape (P,).
    """
    low = np.asarray(pc_range, np.float64)[:3]
    index = np.floor((np.asarray(xyz, np.float64) - low) /
                     np.asarray(voxel_size, np.float64)).astype(np.int64)
    inside = np.all((index >= 0) & (index < np.asarray(grid_shape)), axis=1)
    return index, inside


def occupancy_point_labels(xyz: np.ndarray,
                           gt_occ: np.ndarray,
                           pc_range: np.ndarray,
                           voxel_size: np.ndarray,
                           ignore_index: int = IGNORE_INDEX) -> np.ndarray:
    """The occupancy label of the voxel each point falls in
    (:func:`point_voxel_index`).

    Args:
        xyz (np.ndarray): Points in the grid's frame. Shape (P, 3).
        gt_occ (np.ndarray): Occupancy labels. Shape (X, Y, Z).
        pc_range (np.ndarray): ``(x0, y0, z0, x1, y1, z1)`` of the grid.
        voxel_size (np.ndarray): Shape (3,), metres.
        ignore_index (int): Label of points outside the grid or in a voxel
            without one of the classes 1..16. Defaults to 255.

    Returns:
        np.ndarray: Shape (P,), int64, in 1..16 or ``ignore_index``.
    """
    grid = np.asarray(gt_occ)
    index, inside = point_voxel_index(xyz, grid.shape, pc_range, voxel_size)
    labels = np.full(len(index), ignore_index, np.int64)
    i, j, k = index[inside].T
    labels[inside] = grid[i, j, k]
    labels[(labels < FIRST_CLASS) | (labels > LAST_CLASS)] = ignore_index
    return labels
