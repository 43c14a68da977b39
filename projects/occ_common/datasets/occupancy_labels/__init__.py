"""Occupancy labels from a nuScenes-format dataset's own LiDAR sequences.

For users without Occ3D or SurroundOcc labels (their own recordings, a
new rig). Each module holds one step, in the order they run:

* :mod:`.sequence`: what the tables and files say (sweeps, key frames,
  annotated tracks), read with nuscenes-devkit;
* :mod:`.accumulation`: every sweep's returns as rays, static points
  (world frame) and object points (box frames, :mod:`.box_frame`);
  :mod:`.no_return`: the fired rays that returned nothing;
* :mod:`.free_space`: carving spurious and moved points out of the static
  scene by the rays that crossed them;
* :mod:`.semantics`: classes from lidarseg and box categories;
* :mod:`.voxelization`: points into a format's grid;
  :mod:`.densification`: unseen ground and object interiors;
* :mod:`.visibility`: ``mask_lidar`` and ``mask_camera`` by ray casting;
* :mod:`.writers`: the Occ3D and SurroundOcc files;
  :mod:`.scene_labels` / :mod:`.generate`: one scene / a dataset.

Entry point: ``tools/dataset_converters/generate_occupancy.py``. Needs
nuscenes-devkit and scipy; imports no model code.
"""
from .config import BASELINES, LabelConfig
from .generate import generate_occupancy
from .scene_labels import FrameLabels, scene_labels, write_scene
from .sequence import SceneSequence, read_scene

__all__ = [
    'BASELINES', 'FrameLabels', 'LabelConfig', 'SceneSequence',
    'generate_occupancy', 'read_scene', 'scene_labels', 'write_scene'
]
