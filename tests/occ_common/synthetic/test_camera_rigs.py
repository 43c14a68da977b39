"""Rigs other than nuScenes': the four-camera rig and a LiDAR without ring
index, and the default world written byte for byte as before."""
import hashlib
import os
import os.path as osp

import numpy as np
import pytest

from projects.occ_common.synthetic import (QUAD_CAMERA_NAMES,
                                           generate_synthetic_nuscenes,
                                           make_camera_rig)
from projects.occ_common.synthetic.layout import build_world
from projects.occ_common.synthetic.lidar import make_lidar2ego, scan_lidar

#: MD5 over the relative path and bytes of every file the generator wrote
#: for the tiny world (tests/conftest.py's ``converted_tiny_world``; the
#: 67 files of images, sweeps, labels, tables and worlds, not meta.json,
#: which holds the run's time), computed with the generator of commit
#: 88faba5 (before the rig options existed).
TINY_WORLD_MD5 = '45a4589b6f036e0214de58bef2a16e08'


def _generator_files_md5(root: str) -> tuple:
    """(file count, MD5) of what the generator wrote under ``root``: the
    converter's info files, the tiny-world stamp and meta.json left out."""
    digest, count = hashlib.md5(), 0
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(files):
            rel = osp.relpath(osp.join(folder, name), root)
            if name.endswith('.pkl') or rel in (
                    osp.join('synthetic_gt', 'meta.json'),
                    osp.join('synthetic_gt', 'tiny_world.json')):
                continue
            digest.update(rel.encode())
            with open(osp.join(folder, name), 'rb') as f:
                digest.update(f.read())
            count += 1
    return count, digest.hexdigest()


def test_default_world_is_unchanged(converted_tiny_world):
    """The rig options default to nuScenes' six cameras and a LiDAR with
    ring index, and the default world's files are the same bytes as before
    the options existed."""
    assert _generator_files_md5(converted_tiny_world) == (67, TINY_WORLD_MD5)


def test_quad_rig_looks_every_way():
    """Four cameras at yaws 0, 90, 180, -90 deg (within the 0.6 deg of
    mount tilt and no jitter), each 100 deg wide: fx = 800 / tan(50 deg) =
    671.3 px at 1600x900, so neighbours overlap by 10 deg; square pixels
    (fy = fx) at any 16:9 size."""
    rig = make_camera_rig((1600, 900), rig='quad')
    assert [c.name for c in rig] == list(QUAD_CAMERA_NAMES)
    for camera, yaw in zip(rig, (0, 90, 180, -90)):
        axis = camera.cam2ego[:3, 2]
        error = (np.degrees(np.arctan2(axis[1], axis[0])) - yaw + 180) % 360
        assert abs(error - 180) < 0.6
        k = camera.intrinsic
        assert k[0, 0] == pytest.approx(671.3, abs=0.1) == k[1, 1]
        assert np.degrees(2 * np.arctan(800 / k[0, 0])) == pytest.approx(
            100.0)
    small = make_camera_rig((160, 90), rig='quad')[0].intrinsic
    assert small[0, 0] == pytest.approx(small[1, 1])
    with pytest.raises(ValueError, match='rig'):
        make_camera_rig((160, 90), rig='hexa')


def test_lidar_without_ring_index_keeps_the_points():
    """The same sweep with and without ring index (same world, pose and
    random stream): x, y, z, intensity are identical, the ring column is
    the only difference (beam indices 0..31)."""
    world = build_world(np.random.default_rng(3), 1.0, False, False)
    pose = world.ego_pose(0.0) @ make_lidar2ego()
    ring = scan_lidar(world, pose, 0.0, 32, np.random.default_rng(7))
    plain = scan_lidar(world, pose, 0.0, 32, np.random.default_rng(7),
                       with_ring=False)
    assert ring.points.shape[1] == 5 and plain.points.shape[1] == 4
    np.testing.assert_array_equal(plain.points, ring.points[:, :4])
    assert set(np.unique(ring.points[:, 4])) <= set(range(32))
    np.testing.assert_array_equal(plain.raw_class, ring.raw_class)


def test_generator_refuses_unknown_rig_options(tmp_path):
    with pytest.raises(ValueError, match='camera_rig'):
        generate_synthetic_nuscenes(str(tmp_path), camera_rig='hexa')
    with pytest.raises(ValueError, match='lidar_ring'):
        generate_synthetic_nuscenes(str(tmp_path), lidar_ring='no')
