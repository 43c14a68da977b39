"""The settings of the occupancy label generator, with their reasons."""
import json
from dataclasses import dataclass, fields
from typing import Dict, Tuple


@dataclass(frozen=True)
class LabelConfig:
    """How labels are made from a scene's sweeps.

    Args:
        accumulate (bool): Use every sweep of the scene. False: each key
            frame's own sweep only (the "key frame alone" baseline).
            Defaults to True.
        box_frame (bool): Accumulate annotated objects in their box frames
            and place them at each key frame's box. False: every point is
            accumulated in the world frame (moving objects smear; the
            "no box-frame alignment" baseline). Defaults to True.
        box_margin (float): Growth of a box's sides and top when points
            are assigned to it, metres: absorbs the LiDAR's range noise
            (a surface point measured a few cm behind the face) and the
            slack of hand-drawn boxes. Defaults to 0.2.
        ground_clearance (float): Rise of a box's bottom when points are
            assigned to it, metres: the ground under and around a car
            stays with the static scene (a ground point inside the grown
            box would otherwise be carried along with the car).
            Defaults to 0.1.
        max_extrapolation (float): Seconds a box is extrapolated before
            its first and after its last annotation: one key-frame
            interval of nuScenes (2 Hz), which covers the sweeps before a
            scene's first key frame. Defaults to 0.5.
        carve_voxel (float): Voxel edge of the world grid in which rays
            carve free space from the static points, metres: the Occ3D
            voxel. Defaults to 0.4.
        min_hit_ratio (float): A static point survives when, in its world
            voxel, returns make up at least this share of returns plus
            rays that passed through. Spurious returns (rain, dust) in
            open air are passed through by hundreds of rays; surfaces,
            even hit at grazing angles, by few. Defaults to 0.1.
        label_radius (float): A static point without a lidarseg label
            (sweeps between key frames) takes the class of the nearest
            labelled static point within this distance, metres, else
            ``others``. Defaults to inf: lidarseg labels only key frames,
            and the ground between their rings is metres from the
            nearest labelled return.
        ground_fill_radius (float): Densification: a grid column with
            nothing near the ground takes the ground layer (height and
            class) of the nearest observed ground column within this
            distance, metres; 0 disables. Defaults to inf: the ground
            runs on under what the LiDAR did not see (its beams' circles
            leave rings of unseen ground, and all of it beyond ~30 m);
            lower it where the terrain is not continuous.
        surface_depth (float): Each return is voxelised this many voxel
            edges behind the surface it hit, along its ray. 0 labels the
            voxel that holds the return (a voxel is occupied when any
            part of it is solid, as Occ3D and SurroundOcc voxelise their
            points); 0.25 matches grids that count a voxel occupied when
            the solid covers one of its 2 x 2 x 2 interior sample points
            (the synthetic world's exact labels). Defaults to 0.
        fill_objects (bool): Densification: fill each object's voxels
            inside the convex hull of its accumulated points (the
            interior a LiDAR never sees). Defaults to True.
        no_return_range (float): Fired rays without a return (recovered
            from the rings' pattern, :mod:`.no_return`) cross this many
            metres of free space in ``mask_lidar``: nuScenes' LiDAR range
            (Caesar et al., CVPR 2020: 70 m); 0 leaves them out (the mask
            of the returns only). Defaults to 70.0.
        mask_sweeps (int): Sweeps whose rays make ``mask_lidar``: the key
            frame's and the ones before it (nuScenes' 10 sweeps of one
            key-frame interval, mmdet3d's usual ``max_sweeps``).
            Defaults to 10.
        camera_ray_spacing (float): ``mask_camera`` casts one ray per
            pixel block such that neighbouring rays are at most this far
            apart at 40 m (the Occ3D grid's half width), metres: one
            Occ3D voxel. Half of it casts 2.3x the rays for the same mask
            (0.830 against 0.831 IoU with the exact mask of the synthetic
            world). Defaults to 0.4.
        ego_box (Tuple[float, ...]): Returns inside this ego-frame box
            ``(x0, y0, z0, x1, y1, z1)`` are the car itself and are
            dropped (nuScenes' Renault Zoe with 0.3 m to spare).
            Defaults to (-1.3, -1.2, -0.5, 3.3, 1.2, 2.3).
    """
    accumulate: bool = True
    box_frame: bool = True
    box_margin: float = 0.2
    ground_clearance: float = 0.1
    max_extrapolation: float = 0.5
    carve_voxel: float = 0.4
    min_hit_ratio: float = 0.1
    label_radius: float = float('inf')
    ground_fill_radius: float = float('inf')
    surface_depth: float = 0.0
    fill_objects: bool = True
    no_return_range: float = 70.0
    mask_sweeps: int = 10
    camera_ray_spacing: float = 0.4
    ego_box: Tuple[float, ...] = (-1.3, -1.2, -0.5, 3.3, 1.2, 2.3)

    def to_dict(self) -> dict:
        """The settings as JSON values (written beside the labels, and
        compared with them as read back: tuples become lists)."""
        return json.loads(json.dumps(
            {f.name: getattr(self, f.name) for f in fields(self)}))


#: The two baselines the generated labels are measured against
#: (``tools/analysis_tools/benchmark_generated_labels.py``), as changes to
#: the defaults; ``generate_occupancy.py --key-frame-only / --no-box-frame``
#: make the same. ``key-frame``: each key frame's own sweep voxelised as it
#: is, without carving (its own rays would carve its own returns) or
#: densification. ``no-box-frame``: everything accumulated in the world
#: frame (moving objects smear), the other steps as the defaults.
BASELINES: Dict[str, dict] = {
    'key-frame': dict(accumulate=False, min_hit_ratio=0.0,
                      ground_fill_radius=0.0, fill_objects=False),
    'no-box-frame': dict(box_frame=False),
}
