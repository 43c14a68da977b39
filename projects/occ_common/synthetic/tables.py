"""nuScenes database tables (the ``v1.0-*/*.json`` files).

:class:`NuScenesTables` collects records with the fields of nuScenes'
schema (https://www.nuscenes.org/nuscenes#data-format) and writes every
table ``nuscenes.NuScenes`` loads, plus ``lidarseg.json``. Tokens are
32-digit hex strings derived from the generator's seed and a record's
identity, so the same seed always gives the same tokens.
"""
import hashlib
import json
import os
import os.path as osp
from typing import Dict, List, Sequence

import numpy as np

from ..datasets.nuscenes_classes import LIDARSEG_RAW_CLASS_NAMES
from .geometry import matrix_to_quaternion

TABLE_NAMES = ('category', 'attribute', 'visibility', 'instance', 'sensor',
               'calibrated_sensor', 'ego_pose', 'log', 'scene', 'sample',
               'sample_data', 'sample_annotation', 'map', 'lidarseg')

ATTRIBUTE_NAMES = ('vehicle.moving', 'vehicle.stopped', 'vehicle.parked',
                   'cycle.with_rider', 'cycle.without_rider',
                   'pedestrian.sitting_lying_down', 'pedestrian.standing',
                   'pedestrian.moving')

#: nuScenes' visibility bins: token -> (level, lower bound of the visible
#: fraction of the object in all camera images).
VISIBILITY_LEVELS = {'1': ('v0-40', 0.0), '2': ('v40-60', 0.4),
                     '3': ('v60-80', 0.6), '4': ('v80-100', 0.8)}


def make_token(seed: int, *parts) -> str:
    """Deterministic nuScenes-style token of a record.

    Args:
        seed (int): The generator's seed.
        *parts: The record's identity, e.g. ``('sample', 3, 1)``.

    Returns:
        str: 32 lowercase hex digits.
    """
    key = '/'.join(str(p) for p in (seed, ) + parts)
    return hashlib.md5(key.encode('utf-8')).hexdigest()


def visibility_token(fraction: float) -> str:
    """nuScenes visibility token of a visible fraction in [0, 1].

    Args:
        fraction (float): Visible fraction of an object.

    Returns:
        str: One of '1'..'4'.
    """
    token = '1'
    for key, (_, lower) in VISIBILITY_LEVELS.items():
        if fraction >= lower:
            token = key
    return token


def _floats(values: Sequence[float]) -> List[float]:
    return [float(v) for v in values]


class NuScenesTables:
    """Accumulates nuScenes records and writes them as JSON tables.

    Args:
        seed (int): The generator's seed (for tokens).
    """

    def __init__(self, seed: int):
        self.seed = seed
        self.tables: Dict[str, List[dict]] = {name: [] for name in
                                              TABLE_NAMES}
        for index, name in enumerate(LIDARSEG_RAW_CLASS_NAMES):
            self.tables['category'].append(dict(
                token=self.category_token(index), name=name,
                description=f'Synthetic-world class {name}.', index=index))
        for name in ATTRIBUTE_NAMES:
            self.tables['attribute'].append(dict(
                token=self.attribute_token(name), name=name,
                description=f'Synthetic-world attribute {name}.'))
        for token, (level, lower) in VISIBILITY_LEVELS.items():
            self.tables['visibility'].append(dict(
                token=token, level=level,
                description=f'visibility of whole object is at least '
                f'{int(lower * 100)}%'))

    def category_token(self, raw_index: int) -> str:
        """Token of the category with a raw lidarseg index."""
        return make_token(self.seed, 'category', raw_index)

    def attribute_token(self, name: str) -> str:
        """Token of an attribute."""
        return make_token(self.seed, 'attribute', name)

    def add(self, table: str, **record) -> dict:
        """Appends one record.

        Args:
            table (str): Table name (one of :data:`TABLE_NAMES`).
            **record: The record's fields, including ``token``.

        Returns:
            dict: The stored record.
        """
        self.tables[table].append(record)
        return record

    def add_sensor(self, token: str, channel: str, modality: str) -> None:
        """Adds a ``sensor`` record."""
        self.add('sensor', token=token, channel=channel, modality=modality)

    def add_calibrated_sensor(self, token: str, sensor_token: str,
                              sensor2ego: np.ndarray,
                              intrinsic: np.ndarray = None) -> None:
        """Adds a ``calibrated_sensor`` record from a 4x4 transform."""
        self.add('calibrated_sensor', token=token, sensor_token=sensor_token,
                 translation=_floats(sensor2ego[:3, 3]),
                 rotation=_floats(matrix_to_quaternion(sensor2ego[:3, :3])),
                 camera_intrinsic=[] if intrinsic is None else
                 [_floats(row) for row in intrinsic])

    def add_ego_pose(self, token: str, timestamp: int,
                     ego2global: np.ndarray) -> None:
        """Adds an ``ego_pose`` record from a 4x4 transform."""
        self.add('ego_pose', token=token, timestamp=int(timestamp),
                 rotation=_floats(matrix_to_quaternion(ego2global[:3, :3])),
                 translation=_floats(ego2global[:3, 3]))

    def write(self, table_dir: str) -> List[str]:
        """Writes every table as ``<table_dir>/<name>.json``.

        Args:
            table_dir (str): Target folder (created if missing).

        Returns:
            List[str]: Paths written.
        """
        os.makedirs(table_dir, exist_ok=True)
        paths = []
        for name in TABLE_NAMES:
            path = osp.join(table_dir, f'{name}.json')
            with open(path, 'w') as f:
                json.dump(self.tables[name], f, indent=0)
            paths.append(path)
        return paths
