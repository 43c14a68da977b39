"""Tests of the previous key-frame links and ``LoadPreviousKeyFrames`` on
the tiny synthetic world (one scene, key frames 0 and 1)."""
import os.path as osp

import mmengine
import numpy as np
import pytest
import torch
from mmdet3d.registry import DATASETS
from mmdet3d.utils import register_all_modules

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.datasets.converters.key_frame_links import \
    link_previous_key_frames

IMG_SIZE = (48, 80)
register_all_modules(init_default_scope=True)


def pipeline(train=False, **loader):
    aug = dict(type='MultiViewImageAug', final_size=IMG_SIZE,
               test_mode=not train)
    if train:
        aug.update(resize_range=(0.9, 1.1), crop_x_range=(0.0, 1.0),
                   flip_prob=0.5, rot_range=(-5.0, 5.0))
    return [
        dict(type='LoadOccPointsFromFile', coord_type='LIDAR', load_dim=5,
             use_dim=5),
        dict(type='LoadMultiViewImagesOcc'), aug,
        dict(type='PointsToEgoFrame'),
        dict(type='OccBEVAug', flip_x_prob=float(train),
             flip_y_prob=0.0, test_mode=not train),
        dict(type='LoadPreviousKeyFrames', num_frames=2, load_points=True,
             **loader),
    ]


def dataset(root, **kwargs):
    return DATASETS.build(dict(
        type='NuScenesOccDataset', data_root=root, occ_format='occ3d',
        ann_file='nuscenes_occ_infos_train.pkl', test_mode=True,
        **dict(dict(num_frames=2), **kwargs)))


def test_converter_links_the_previous_key_frame(converted_tiny_world):
    """Key frame 0 starts the scene (link None); key frame 1 links key
    frame 0 with its token, ego pose, LiDAR file and six images."""
    infos = mmengine.load(osp.join(converted_tiny_world,
                                   'nuscenes_occ_infos_train.pkl'))
    first, second = infos['data_list']
    assert first['prev_key_frame'] is None
    link = second['prev_key_frame']
    assert link['token'] == first['token'] == second['prev']
    assert link['ego2global'] == first['ego2global']
    assert link['lidar_points'] == first['lidar_points']
    assert link['images'] == first['images'] and len(link['images']) == 6
    with pytest.raises(ValueError, match='a scene must be whole'):
        link_previous_key_frames([dict(second)])


def test_first_frame_repeats_itself(converted_tiny_world):
    """Key frame 0 has no predecessor: its previous frame is itself, so
    prev2curr is the identity and the previous views and matrices equal
    the current ones (also under training augmentation with a BEV flip:
    the same parameters are applied)."""
    for train in (False, True):
        ds = dataset(converted_tiny_world, pipeline=pipeline(train))
        out = ds.pipeline(ds.get_data_info(0))
        assert out['prev_tokens'] == [out['token']]
        np.testing.assert_allclose(out['prev2curr'][0], np.eye(4),
                                   atol=1e-9)
        assert len(out['img']) == 12
        for cur, prev in zip(out['img'][:6], out['img'][6:]):
            assert np.array_equal(cur, prev)
        np.testing.assert_allclose(out['prev_lidar2img'][0],
                                   out['lidar2img'], atol=1e-6)
        np.testing.assert_allclose(out['prev_points'][0][:, :3],
                                   out['points'].tensor[:, :3].numpy(),
                                   atol=1e-4)


def test_previous_points_align_with_the_current_frame(converted_tiny_world):
    """Key frame 1 (ego frame, no BEV aug): prev2curr = E1^-1 E0 moves the
    ego by |t0 - t1| = 2.44 m (rotations keep lengths), and maps key frame
    0's above-ground points (z > 0.5 m, within 30 m) onto the surfaces key
    frame 1 sees: the median distance to the nearest current point (the
    world's 4.5-degree LiDAR azimuth spacing keeps it from 0) is under
    0.75 m and under 0.7 times that of the unaligned points or of points
    moved by the inverse motion."""
    ds = dataset(converted_tiny_world, pipeline=pipeline())
    out = ds.pipeline(ds.get_data_info(1))
    infos = [ds.get_data_info(i) for i in (0, 1)]
    assert out['prev_tokens'] == [infos[0]['token']]
    rel = out['prev2curr'][0]
    moved = np.linalg.norm(infos[0]['ego2global'][:3, 3]
                           - infos[1]['ego2global'][:3, 3])
    assert moved > 0.5
    assert np.linalg.norm(rel[:3, 3]) == pytest.approx(moved, abs=1e-6)
    cur = torch.from_numpy(out['points'].tensor[:, :3].numpy()).double()
    prev = torch.from_numpy(out['prev_points'][0][:, :3]).double()
    keep = (prev.norm(dim=1) < 30) & (prev[:, 2] > 0.5)
    prev = prev[keep][::3]

    def median_gap(pts):
        return torch.cdist(pts, cur).min(1).values.median().item()

    aligned = prev @ torch.from_numpy(rel[:3, :3]).T + torch.from_numpy(
        rel[:3, 3])
    inv = torch.from_numpy(np.linalg.inv(rel))
    wrong = prev @ inv[:3, :3].T + inv[:3, 3]
    # Measured: 0.66 m aligned, 1.11 m unaligned, 1.17 m backwards.
    assert median_gap(aligned) < 0.75
    assert median_gap(aligned) < 0.7 * median_gap(prev)
    assert median_gap(aligned) < 0.7 * median_gap(wrong)


def test_missing_links_are_refused(world_copy):
    """An info file written before the links is refused by a temporal
    dataset, with what to do, and still read by a single-frame one."""
    path = osp.join(world_copy, 'nuscenes_occ_infos_train.pkl')
    infos = mmengine.load(path)
    for entry in infos['data_list']:
        entry.pop('prev_key_frame')
    mmengine.dump(infos, path)
    with pytest.raises(ValueError, match='no prev_key_frame link, needed '
                       'by num_frames=2; re-create'):
        dataset(world_copy)
    assert len(dataset(world_copy, num_frames=1)) == 2  # not needed: fine


def test_dataset_without_num_frames_is_refused(converted_tiny_world):
    ds = dataset(converted_tiny_world, pipeline=pipeline())
    info = ds.get_data_info(1)
    info.pop('prev_frames')
    with pytest.raises(ValueError, match='Build the dataset with '
                       'num_frames=2'):
        ds.pipeline(info)
