"""tools/create_data.py as mmdet3d's: --version v1.0, --workers, progress,
and a conversion that reports what it skipped instead of aborting.

Each test converts its own copy of the one-scene tiny world (two key
frames, each linking up to 10 sweeps).
"""
import json
import os
import os.path as osp
import re
import shutil

import mmengine
import pytest
from PIL import Image

from projects.occ_common.fileio.safe_pickle import load_info_file
from projects.occ_common.testing.mmdet3d_infos import write_mmdet3d_info_file
from projects.occ_common.testing.tool_logs import run_create_data
from projects.occ_common.transforms import LoadMultiViewImagesOcc

pytestmark = pytest.mark.filterwarnings(
    'ignore:synthetic world with one scene')
TRAIN = 'nuscenes_occ_infos_train.pkl'


def _infos(root, split='train'):
    return load_info_file(osp.join(root, f'nuscenes_occ_infos_{split}.pkl'))


def test_version_v1_0_is_trainval_and_test(world_copy):
    """mmdet3d's default --version v1.0 converts v1.0-trainval and then
    v1.0-test: with both table folders (the tiny world's tables copied
    under both names) it writes the four trainval splits and the test
    split (of a synthetic world: every scene). Before, v1.0 was taken as a
    folder name and failed."""
    for version in ('v1.0-trainval', 'v1.0-test'):
        shutil.copytree(osp.join(world_copy, 'v1.0-mini'),
                        osp.join(world_copy, version))
        shutil.copytree(osp.join(world_copy, 'lidarseg', 'v1.0-mini'),
                        osp.join(world_copy, 'lidarseg', version))
    written = run_create_data('--root-path', world_copy, '--version', 'v1.0',
                              '--overwrite')
    assert sorted(written) == ['test', 'train', 'val', 'val_night',
                               'val_rainy']
    assert _infos(world_copy, 'test')['metainfo']['version'] == 'v1.0-test'
    assert _infos(world_copy)['metainfo']['version'] == 'v1.0-trainval'
    assert len(_infos(world_copy, 'test')['data_list']) == 2


def test_workers_give_the_same_infos_and_show_progress(world_copy, capsys):
    """--workers 2 writes exactly the infos of --workers 0 (same order,
    same content); both print the split's sample count (also of the rainy
    and night subsets) and a progress bar that reaches 2/2."""
    run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                    '--overwrite', '--workers', '0')
    alone = _infos(world_copy)
    out = capsys.readouterr().out
    assert 'v1.0-mini train: 2 samples of 1 scenes' in out
    for split, word in (('val_rainy', 'rain'), ('val_night', 'night')):
        entries = _infos(world_copy, split)['data_list']
        scenes = len({e['scene_token'] for e in entries})
        assert (f'v1.0-mini {split}: {len(entries)} samples of {scenes} '
                f'scenes (description mentions {word})') in out
    assert '2/2' in out
    run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                    '--overwrite', '--workers', '2')
    assert _infos(world_copy) == alone
    assert '2/2' in capsys.readouterr().out


def test_keyframe_only_download_is_converted(world_copy):
    """Without sweeps/ (a keyframe-only download) every sample links no
    sweep and the conversion says so once per sample; with one sweep file
    missing, its sample keeps the sweeps before it. Before, the first
    missing sweep aborted the conversion."""
    first = _infos(world_copy)['data_list'][0]
    gap = first['lidar_sweeps'][3]['lidar_points']['lidar_path']
    os.remove(osp.join(world_copy, gap))
    with pytest.warns(UserWarning,
                      match=r'missing LiDAR sweeps.*: 1 \(sample'):
        run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                        '--overwrite')
    after = _infos(world_copy)['data_list']
    assert after[0]['lidar_sweeps'] == first['lidar_sweeps'][:3]
    shutil.rmtree(osp.join(world_copy, 'sweeps'))
    with pytest.warns(UserWarning, match=r'missing LiDAR sweeps.*: 2 \('):
        run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                        '--overwrite')
    assert all(e['lidar_sweeps'] == []
               for e in _infos(world_copy)['data_list'])


@pytest.mark.parametrize('key, kind', [
    ('occ_surroundocc_path', 'SurroundOcc label'),
    ('occ_occ3d_path', 'Occ3D label'),
    ('pts_semantic_mask_path', 'lidarseg label'),
])
def test_one_missing_label_is_reported(world_copy, key, kind):
    """One deleted label file: the sample records None for it (training
    skips it, evaluation names it, SDG's 2-D targets fall back to the
    occupancy labels), the other sample keeps its label, and the report
    names the file. Before, the conversion stopped."""
    first = _infos(world_copy)['data_list'][0]
    os.remove(osp.join(world_copy, first[key]))
    with pytest.warns(UserWarning, match=f'missing {kind}.*: 1 .*' +
                      re.escape(osp.basename(first[key]))):
        run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                        '--overwrite')
    entries = _infos(world_copy)['data_list']
    assert entries[0][key] is None and entries[1][key] is not None


def test_panoptic_table_without_files_is_ignored(world_copy):
    """A panoptic.json whose files were never unpacked made
    nuscenes-devkit fail (no panoptic/ folder); it is now hidden from the
    devkit and reported, and the infos are those of a clean root."""
    clean = _infos(world_copy)
    records = [dict(token=f'p{i}', sample_data_token='x',
                    filename=f'panoptic/v1.0-mini/p{i}_panoptic.npz')
               for i in range(3)]
    mmengine.dump(records,
                  osp.join(world_copy, 'v1.0-mini', 'panoptic.json'))
    with pytest.warns(UserWarning, match='panoptic table without its files'):
        run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                        '--overwrite')
    assert _infos(world_copy)['data_list'] == clean['data_list']


def test_missing_key_frame_still_stops(world_copy):
    """A missing key frame is not safe to skip (the sample has no input):
    the conversion stops, naming it."""
    first = _infos(world_copy)['data_list'][0]
    os.remove(osp.join(world_copy, first['lidar_points']['lidar_path']))
    with pytest.raises(FileNotFoundError, match='LiDAR key frame'):
        run_create_data('--root-path', world_copy, '--version', 'v1.0-mini',
                        '--overwrite')


def test_extend_mmdet3d_info_file(world_copy, tmp_path):
    """An mmdet3d v2 info file of the world (bare file names as mmdet3d
    writes them, sweeps as data/nuscenes/sweeps/... paths, no scene keys,
    no image sizes) is extended to exactly the entries our converter
    wrote: the same paths below the root, matrices, scene (from the
    tables), labels, and image height / width (read from the files;
    before, they were not recorded, and a view resized after the
    conversion loaded without an error)."""
    ours = _infos(world_copy)['data_list']
    mmdet3d_file = write_mmdet3d_info_file(
        str(tmp_path / 'nuscenes_infos_train.pkl'), ours)
    out = str(tmp_path / 'out')
    written = run_create_data('--root-path', world_copy, '--out-dir', out,
                              '--from-mmdet3d-info', mmdet3d_file)
    assert written == dict(train=osp.join(out, TRAIN))
    extended = load_info_file(written['train'])
    assert extended['metainfo']['extended_from'] == \
        'nuscenes_infos_train.pkl'
    for got, want in zip(extended['data_list'], ours):
        for key, value in want.items():
            if key in ('lidar_sweeps', 'images', 'prev_key_frame'):
                continue
            assert got[key] == value, key
        # Both converters link the same previous key frame (its images by
        # path: their calibration is compared as the sample's own).
        assert (got['prev_key_frame'] is None) == (
            want['prev_key_frame'] is None)
        if want['prev_key_frame'] is not None:
            for key in ('token', 'ego2global', 'lidar_points'):
                assert got['prev_key_frame'][key] == \
                    want['prev_key_frame'][key], key
            assert {c: i['img_path'] for c, i in
                    got['prev_key_frame']['images'].items()} == {
                c: i['img_path'] for c, i in
                want['prev_key_frame']['images'].items()}
        assert [s['lidar_points']['lidar_path'] for s in got['lidar_sweeps']
                ] == [s['lidar_points']['lidar_path']
                      for s in want['lidar_sweeps']]
        for key in ('img_path', 'height', 'width'):
            assert {c: i[key] for c, i in got['images'].items()} == {
                c: i[key] for c, i in want['images'].items()}, key
    assert json.dumps(extended['metainfo']['classes']) == json.dumps(
        _infos(world_copy)['metainfo']['classes'])

    # A view resized by 0.8 after the conversion: refused when loaded,
    # naming the sample and the camera.
    sample = extended['data_list'][0]
    images = {
        cam: dict(info, img_path=osp.join(world_copy, info['img_path']))
        for cam, info in sample['images'].items()
    }
    front = images['CAM_FRONT']['img_path']
    with Image.open(front) as img:
        img.resize((img.width * 4 // 5, img.height * 4 // 5)).save(
            front, format=img.format)
    with pytest.raises(ValueError,
                       match=re.escape(
                           f'sample {sample["token"]} CAM_FRONT: image '
                           f'{front} is 128x72, but its calibration')):
        LoadMultiViewImagesOcc().transform(
            dict(token=sample['token'], images=images))
