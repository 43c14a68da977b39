"""Which cameras the converter links, in which order (hand-made tables)."""
import pytest

from projects.occ_common.datasets.converters.nuscenes_occ_converter import \
    rig_cameras
from projects.occ_common.datasets.info_format import CAMERA_NAMES, camera_order


def _sensors(*channels):
    return [dict(channel=c, modality='lidar' if c == 'LIDAR_TOP' else
                 'camera') for c in channels]


def test_nuscenes_cameras_take_mmdet3d_order():
    """nuScenes' sensor table lists its cameras in another order (and a
    LiDAR): they come back in mmdet3d's, CAM_FRONT, CAM_FRONT_RIGHT,
    CAM_FRONT_LEFT, CAM_BACK, CAM_BACK_LEFT, CAM_BACK_RIGHT."""
    table = _sensors('CAM_BACK', 'LIDAR_TOP', *sorted(CAMERA_NAMES))
    assert rig_cameras(table) == CAMERA_NAMES


def test_other_rigs_keep_their_table_order():
    """Four cameras (two of them nuScenes names) keep the table's order;
    a name listed twice counts once; a table without cameras is refused
    naming its channels."""
    table = _sensors('CAM_FRONT', 'CAM_LEFT', 'LIDAR_TOP', 'CAM_BACK',
                     'CAM_RIGHT')
    assert rig_cameras(table) == ('CAM_FRONT', 'CAM_LEFT', 'CAM_BACK',
                                  'CAM_RIGHT')
    assert camera_order(['B', 'A', 'B']) == ('B', 'A')
    with pytest.raises(ValueError, match=r"\['LIDAR_TOP'\]"):
        rig_cameras(_sensors('LIDAR_TOP'))
