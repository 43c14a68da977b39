"""nuScenes-lidarseg raw classes and the 16 occupancy classes.

One neutral home for the class tables that the synthetic world generator,
the converter, the dataset, the transforms and the metrics all share, so that
no two of them can disagree on an index.

* nuScenes-lidarseg labels every LiDAR point with one of 32 raw classes
  (``category.json``'s ``index`` field; 0 is ``noise``).
* SurroundOcc and Occ3D-nuScenes use the 16 classes of the nuScenes-lidarseg
  challenge, numbered 1..16 (:data:`OCC_CLASS_NAMES`). Label 0 is ``noise``
  in SurroundOcc's sparse ``.npy`` files and ``others`` in Occ3D's
  ``labels.npz``; Occ3D marks empty voxels with 17 (:data:`OCC3D_FREE_LABEL`).

:data:`LIDARSEG_RAW_TO_OCC16` is the official fine-to-coarse mapping of the
nuScenes-lidarseg challenge (``nuscenes.eval.lidarseg.utils.
LidarsegClassMapper``), written out as a lookup table. The raw classes the
challenge ignores (animals, strollers, emergency vehicles, debris, ...) map
to 0.
"""
from typing import Dict, Tuple

import numpy as np

#: The 32 raw nuScenes-lidarseg classes, indexed by ``category['index']``.
LIDARSEG_RAW_CLASS_NAMES: Tuple[str, ...] = (
    'noise',                                 # 0
    'animal',                                # 1
    'human.pedestrian.adult',                # 2
    'human.pedestrian.child',                # 3
    'human.pedestrian.construction_worker',  # 4
    'human.pedestrian.personal_mobility',    # 5
    'human.pedestrian.police_officer',       # 6
    'human.pedestrian.stroller',             # 7
    'human.pedestrian.wheelchair',           # 8
    'movable_object.barrier',                # 9
    'movable_object.debris',                 # 10
    'movable_object.pushable_pullable',      # 11
    'movable_object.trafficcone',            # 12
    'static_object.bicycle_rack',            # 13
    'vehicle.bicycle',                       # 14
    'vehicle.bus.bendy',                     # 15
    'vehicle.bus.rigid',                     # 16
    'vehicle.car',                           # 17
    'vehicle.construction',                  # 18
    'vehicle.emergency.ambulance',           # 19
    'vehicle.emergency.police',              # 20
    'vehicle.motorcycle',                    # 21
    'vehicle.trailer',                       # 22
    'vehicle.truck',                         # 23
    'flat.driveable_surface',                # 24
    'flat.other',                            # 25
    'flat.sidewalk',                         # 26
    'flat.terrain',                          # 27
    'static.manmade',                        # 28
    'static.other',                          # 29
    'static.vegetation',                     # 30
    'vehicle.ego',                           # 31
)

#: The 16 occupancy classes; the class with label ``k`` is entry ``k - 1``.
OCC_CLASS_NAMES: Tuple[str, ...] = (
    'barrier', 'bicycle', 'bus', 'car', 'construction_vehicle', 'motorcycle',
    'pedestrian', 'traffic_cone', 'trailer', 'truck', 'driveable_surface',
    'other_flat', 'sidewalk', 'terrain', 'manmade', 'vegetation')

#: Label of ignored points / voxels (SurroundOcc ``noise``, Occ3D
#: ``others``).
OCC_NOISE_LABEL = 0
#: Label of empty voxels in Occ3D's ``semantics``.
OCC3D_FREE_LABEL = 17
#: Occ3D's 18 names: ``others``, the 16 classes, ``free``.
OCC3D_CLASS_NAMES: Tuple[str, ...] = ('others', ) + OCC_CLASS_NAMES + (
    'free', )

# Coarse name of every raw class; None = ignored by the challenge (label 0).
_RAW_TO_COARSE: Dict[str, str] = {
    'human.pedestrian.adult': 'pedestrian',
    'human.pedestrian.child': 'pedestrian',
    'human.pedestrian.construction_worker': 'pedestrian',
    'human.pedestrian.police_officer': 'pedestrian',
    'movable_object.barrier': 'barrier',
    'movable_object.trafficcone': 'traffic_cone',
    'vehicle.bicycle': 'bicycle',
    'vehicle.bus.bendy': 'bus',
    'vehicle.bus.rigid': 'bus',
    'vehicle.car': 'car',
    'vehicle.construction': 'construction_vehicle',
    'vehicle.motorcycle': 'motorcycle',
    'vehicle.trailer': 'trailer',
    'vehicle.truck': 'truck',
    'flat.driveable_surface': 'driveable_surface',
    'flat.other': 'other_flat',
    'flat.sidewalk': 'sidewalk',
    'flat.terrain': 'terrain',
    'static.manmade': 'manmade',
    'static.vegetation': 'vegetation',
}


def _build_raw_to_occ16() -> np.ndarray:
    """Builds the read-only raw-index -> occupancy-label lookup table."""
    table = np.zeros(len(LIDARSEG_RAW_CLASS_NAMES), dtype=np.uint8)
    for raw_index, raw_name in enumerate(LIDARSEG_RAW_CLASS_NAMES):
        coarse = _RAW_TO_COARSE.get(raw_name)
        if coarse is not None:
            table[raw_index] = OCC_CLASS_NAMES.index(coarse) + 1
    table.setflags(write=False)
    return table


#: Shape (32,), uint8: occupancy label (0..16) of each raw lidarseg class,
#: e.g. raw 17 ``vehicle.car`` -> 4, raw 24 ``flat.driveable_surface`` -> 11,
#: raw 30 ``static.vegetation`` -> 16, raw 0 ``noise`` -> 0. Read-only.
LIDARSEG_RAW_TO_OCC16: np.ndarray = _build_raw_to_occ16()

#: RGB colour of every Occ3D label 0..17 (the nuScenes-lidarseg challenge
#: palette for 1..16; black for ``others``, white for ``free``), for
#: visualisation. Shape (18, 3), uint8. Read-only.
OCC_CLASS_PALETTE: np.ndarray = np.array(
    [[0, 0, 0], [112, 128, 144], [220, 20, 60], [255, 127, 80],
     [255, 158, 0], [233, 150, 70], [255, 61, 99], [0, 0, 230],
     [47, 79, 79], [255, 140, 0], [255, 99, 71], [0, 207, 191],
     [175, 0, 75], [75, 0, 75], [112, 180, 60], [222, 184, 135],
     [0, 175, 0], [255, 255, 255]],
    dtype=np.uint8)
OCC_CLASS_PALETTE.setflags(write=False)


def lidarseg_to_occ16(raw_labels: np.ndarray, source: str = '') -> np.ndarray:
    """Maps raw nuScenes-lidarseg labels to the 16 occupancy classes.

    Args:
        raw_labels (np.ndarray): Raw class indices 0..31, any integer dtype.
            Shape (N,) or any shape.
        source (str): Where the labels come from (e.g. the ``.bin`` path),
            named in the error message. Defaults to ''.

    Returns:
        np.ndarray: Occupancy labels 0..16 (0 = noise / ignored), uint8.
        Same shape as ``raw_labels``.

    Raises:
        ValueError: If ``raw_labels`` is not an integer array or holds a
            value outside 0..31.
    """
    raw_labels = np.asarray(raw_labels)
    where = f' in {source}' if source else ''
    if not np.issubdtype(raw_labels.dtype, np.integer):
        raise ValueError('Expected integer nuScenes-lidarseg labels'
                         f'{where}, got dtype {raw_labels.dtype}.')
    if raw_labels.size and (raw_labels.min() < 0 or raw_labels.max() >= len(
            LIDARSEG_RAW_CLASS_NAMES)):
        raise ValueError(
            'Expected nuScenes-lidarseg labels in 0..'
            f'{len(LIDARSEG_RAW_CLASS_NAMES) - 1}{where}, got values in '
            f'{raw_labels.min()}..{raw_labels.max()}.')
    return LIDARSEG_RAW_TO_OCC16[raw_labels]
