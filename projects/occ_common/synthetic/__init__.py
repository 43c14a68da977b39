"""A generator of small, geometrically consistent nuScenes-format worlds.

Plain numpy / OpenCV / json: importing it registers nothing. The entry
point is :func:`generate_synthetic_nuscenes`; the command line is
``tools/dataset_converters/create_synthetic_nuscenes.py``. Each module
holds one concept:

* :mod:`.world` / :mod:`.layout`: a scene's 3D world and how it is laid out;
* :mod:`.raycast`: ray casting shared by the cameras and the LiDAR;
* :mod:`.camera` / :mod:`.textures`: the camera rigs (nuScenes' six
  cameras, a four-camera rig) and the renderer;
* :mod:`.lidar`: the 32-beam spinning LiDAR;
* :mod:`.occupancy`: SurroundOcc / Occ3D ground truth and visibility masks;
* :mod:`.tables` / :mod:`.scene_writer` / :mod:`.generate`: the nuScenes
  tables and files.

Beside the world, imported directly (they need mmdet3d): random batches of
a config's shapes (:mod:`.synthetic_batch`), hand-made camera rigs and
tiny occupancy batches (:mod:`.occ_inputs`) and the world's per-pixel
classes as the network sees them (:mod:`.camera_classes`).
"""
from .camera import (CAMERA_NAMES, CAMERA_RIGS, QUAD_CAMERA_NAMES, Camera,
                     make_camera_rig)
from .generate import (CONDITIONS, DEFAULT_CONDITIONS, META_PATH,
                       generate_synthetic_nuscenes, load_world)
from .occupancy import OCC3D_GRID, SURROUNDOCC_GRID, OccGrid
from .scene_writer import camera_label_path
from .world import World, world_from_dict

__all__ = [
    'CAMERA_NAMES', 'CAMERA_RIGS', 'CONDITIONS', 'Camera',
    'DEFAULT_CONDITIONS', 'META_PATH', 'OCC3D_GRID', 'OccGrid',
    'QUAD_CAMERA_NAMES', 'SURROUNDOCC_GRID', 'World',
    'camera_label_path', 'generate_synthetic_nuscenes', 'load_world',
    'make_camera_rig', 'world_from_dict'
]
