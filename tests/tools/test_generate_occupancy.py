"""tools/dataset_converters/generate_occupancy.py and its benchmark:
labels a user's pipeline can load, made and scored on tiny worlds."""
import glob
import os
import os.path as osp
import warnings

import numpy as np
import pytest
from mmdet3d.registry import DATASETS
from mmdet3d.utils import register_all_modules

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.analysis.tool_runs import train_label_options
from projects.occ_common.datasets.occupancy_labels import (LabelConfig,
                                                           generate_occupancy)
from projects.occ_common.testing.hand_built_scene import (
    HandSweep, write_hand_built_scene)
from projects.occ_common.testing.tool_logs import load_tool, run_create_data

register_all_modules(init_default_scope=True)


@pytest.fixture(scope='module')
def generated(converted_tiny_world, tmp_path_factory):
    """Labels of the tiny world, made by the command line tool."""
    out = str(tmp_path_factory.mktemp('generated'))
    load_tool('tools/dataset_converters/generate_occupancy.py').main(
        ['--root-path', converted_tiny_world, '--version', 'v1.0-mini',
         '--out-dir', out])
    return out


def test_generated_labels_load_through_the_dataset(converted_tiny_world,
                                                   generated):
    """tools/create_data.py links the generated folders as it links
    Occ3D's and SurroundOcc's (--occ3d-root, --surroundocc-root), and the
    dataset's own loader reads them: both key frames, in both formats,
    the Occ3D grid with its masks, labels 0..17 with ground and free."""
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', 'synthetic world with one scene')
        infos = run_create_data(
            '--root-path', converted_tiny_world, '--version', 'v1.0-mini',
            '--occ3d-root', osp.join(generated, 'gts'), '--surroundocc-root',
            osp.join(generated, 'nuscenes_occ'), '--out-dir', generated)
    for fmt in ('occ3d', 'surroundocc'):
        dataset = DATASETS.build(dict(
            type='NuScenesOccDataset', data_root=converted_tiny_world,
            ann_file=infos['train'], occ_format=fmt,
            coord_frame='ego' if fmt == 'occ3d' else 'lidar',
            pipeline=[dict(type='LoadOccupancyGT')]))
        assert len(dataset) == 2
        for index in range(2):
            sample = dataset[index]
            assert sample['occ_path'].startswith(generated)
            assert sample['gt_occ'].shape == (200, 200, 16)
            ground = np.isin(sample['gt_occ'], [11, 12, 13, 14]).sum()
            assert ground > 10000
        if fmt == 'occ3d':
            assert sample['mask_lidar'].sum() > 0
            assert sample['mask_camera'].sum() > 0
            assert (sample['gt_occ'] == 17).sum() > 0.5 * 200 * 200 * 16


def test_benchmark_ranks_the_variants(converted_tiny_world, generated,
                                      tmp_path):
    """On the tiny world (2 key frames, 80 azimuth steps): the generated
    mask_lidar is the exact one (the same rays, recovered with the ones
    that returned nothing, walked by the same voxel walk); accumulating
    beats the key frame alone in the exact LiDAR mask (box frames against
    the world frame: the hand-built car in test_hand_built_scenes.py).
    ``ours`` is the command line's labels (the defaults), which the
    benchmark resumes instead of making them again. ``--reach``: every
    exact occupied voxel inside the exact mask_lidar (the key frame's
    last sweeps' rays) is reached by the rays of all sweeps, and some are
    reached by none: manmade is solid inside, so under 5 % of it is (the
    shell; the tiny world: 784 of 58,081)."""
    tool = load_tool('tools/analysis_tools/benchmark_generated_labels.py')
    os.symlink(generated, tmp_path / 'ours')
    results = tool.main(['--root-path', converted_tiny_world, '--out',
                         str(tmp_path), '--variants', 'keyframe', 'ours',
                         '--reach'])
    in_mask = 0
    for path in glob.glob(osp.join(converted_tiny_world, 'gts', '*', '*',
                                   'labels.npz')):
        with np.load(path) as f:
            in_mask += ((f['semantics'] != 17) & f['mask_lidar']).sum()
    occupied, reached = (np.array(results['reach'][k])
                         for k in ('occupied', 'reached'))
    assert 0 < in_mask <= reached.sum() < occupied.sum()
    assert (reached <= occupied).all()
    assert reached[15] < 0.05 * occupied[15]
    ours, lidar = results['ours'], 'lidar_mask'
    assert ours['masks']['mask_lidar']['IoU'] > 99.9
    assert ours['samples'] == dict(occ3d=2, surroundocc=2)
    for key in ('IoU', 'mIoU'):
        assert ours['occ3d'][lidar][key] > \
            results['keyframe']['occ3d'][lidar][key] + 40
    with open(tmp_path / 'quality.md') as f:
        assert 'ours (defaults)' in f.read()


def test_train_label_options(converted_tiny_world, generated, tmp_path):
    """The option points the train loader at an info file of the same
    samples whose labels are the generated ones; a labels folder lacking
    one of the world's label files is refused, naming it."""
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', 'synthetic world with one scene')
        options = train_label_options(converted_tiny_world, generated,
                                      str(tmp_path / 'log.txt'))
    key, info = options[0].split('=')
    assert key == 'train_dataloader.dataset.ann_file' and osp.isfile(info)
    dataset = DATASETS.build(dict(
        type='NuScenesOccDataset', data_root=converted_tiny_world,
        ann_file=info, occ_format='occ3d', coord_frame='ego', pipeline=[]))
    assert all(d['occ_path'].startswith(generated)
               for d in dataset.data_list)
    empty = tmp_path / 'empty'
    os.makedirs(empty / 'gts')
    with pytest.raises(SystemExit, match='lacks 2 of the 2 label files'):
        train_label_options(converted_tiny_world, str(empty),
                            str(tmp_path / 'log.txt'))


def test_rerun_skips_finished_scenes_and_redoes_a_killed_one(tmp_path):
    """A finished scene is marked (progress/scene-0001.json) and skipped;
    without its mark (killed before it was written) it is done again and
    its truncated label rewritten (the wall's 20 returns at x = 10.2,
    y -1 .. 1, z = 1 fill y voxels 39 / 0.4 = 97.5 -> 97 to 41 / 0.4 =
    102.5 -> 102: 6 manmade voxels); other settings into the same folder
    are refused, or redo everything with overwrite."""
    wall = np.stack([np.full(20, 10.2), np.linspace(-1, 1, 20),
                     np.full(20, 1.0)], axis=1)
    root = write_hand_built_scene(str(tmp_path / 'root'), [
        HandSweep(0.0, (0, 0), wall, key=True, raw_class=28)])
    out = str(tmp_path / 'labels')
    cfg = LabelConfig(no_return_range=0.0)
    first = generate_occupancy(root, 'v1.0-mini', out, cfg, progress=False)
    assert first['scenes'] == ['scene-0001'] and first['files'] == 2
    again = generate_occupancy(root, 'v1.0-mini', out, cfg, progress=False)
    assert again['scenes'] == [] and again['skipped'] == ['scene-0001']
    label = next(osp.join(d, f) for d, _, files in os.walk(
        osp.join(out, 'gts')) for f in files)
    with open(label, 'wb') as f:
        f.write(b'PK')
    os.remove(osp.join(out, 'progress', 'scene-0001.json'))
    redone = generate_occupancy(root, 'v1.0-mini', out, cfg, progress=False)
    assert redone['scenes'] == ['scene-0001']
    assert (np.load(label)['semantics'] == 15).sum() == 6
    with pytest.raises(FileExistsError, match='other settings'):
        generate_occupancy(root, 'v1.0-mini', out, LabelConfig(),
                           progress=False)
    assert generate_occupancy(root, 'v1.0-mini', out, LabelConfig(),
                              overwrite=True, progress=False)['files'] == 2


def test_missing_sweep_is_reported_missing_key_frame_stops(tmp_path):
    """A keyframe-only download: the sweep between the key frames is
    gone. The labels are made from the rest (the wall the first key frame
    saw is still there, 6 voxels) and the missing file is reported; a
    missing key frame stops the scene, naming the file."""
    wall = np.stack([np.full(20, 10.2), np.linspace(-1, 1, 20),
                     np.full(20, 1.0)], axis=1)
    root = write_hand_built_scene(str(tmp_path / 'root'), [
        HandSweep(0.0, (0, 0), wall, key=True, raw_class=28),
        HandSweep(0.05, (0, 0), wall),
        HandSweep(0.1, (0, 0), wall, key=True, raw_class=28)])
    sweep = next(osp.join(root, 'sweeps', 'LIDAR_TOP', f) for f in
                 os.listdir(osp.join(root, 'sweeps', 'LIDAR_TOP')))
    os.remove(sweep)
    cfg = LabelConfig(no_return_range=0.0)
    with pytest.warns(UserWarning, match='missing LiDAR sweeps'):
        summary = generate_occupancy(root, 'v1.0-mini', str(tmp_path / 'a'),
                                     cfg, progress=False)
    assert summary['key_frames'] == 2
    label = next(osp.join(d, f) for d, _, files in os.walk(
        tmp_path / 'a' / 'gts') for f in files)
    assert (np.load(label)['semantics'] == 15).sum() == 6
    key = next(osp.join(root, 'samples', 'LIDAR_TOP', f) for f in
               os.listdir(osp.join(root, 'samples', 'LIDAR_TOP')))
    os.remove(key)
    with pytest.raises(FileNotFoundError, match='key frame LiDAR file'):
        generate_occupancy(root, 'v1.0-mini', str(tmp_path / 'b'), cfg,
                           progress=False)


@pytest.mark.slow
def test_workers_write_what_one_process_writes(tmp_path):
    """Two scenes labelled by two worker processes: the same bytes per
    label as one process writes (a clear day and a rainy night)."""
    from projects.occ_common.testing.tiny_world import make_tiny_world
    root = make_tiny_world(str(tmp_path / 'world'), num_scenes=2,
                           image_size=(64, 36))
    cfg = LabelConfig()
    both = generate_occupancy(root, 'v1.0-mini', str(tmp_path / 'two'), cfg,
                              workers=2, progress=False)
    assert sorted(both['scenes']) == ['scene-0001', 'scene-0002']
    one = generate_occupancy(root, 'v1.0-mini', str(tmp_path / 'one'), cfg,
                             scenes=['scene-0002'], progress=False)
    assert one['files'] == 4
    for folder, _, files in os.walk(tmp_path / 'one'):
        for name in files:
            if name.endswith(('.npz', '.npy')):
                mine = osp.join(folder, name)
                other = mine.replace(str(tmp_path / 'one'),
                                     str(tmp_path / 'two'))
                with open(mine, 'rb') as a, open(other, 'rb') as b:
                    assert a.read() == b.read(), name


def test_command_line_baselines_are_the_benchmarks():
    """``--key-frame-only`` / ``--no-box-frame`` make the labels the
    quality benchmark scores as its baselines: the key frame alone also
    without carving and densification (with densification it would be a
    different, better baseline than the one reported)."""
    tool = load_tool('tools/dataset_converters/generate_occupancy.py')
    bench = load_tool('tools/analysis_tools/benchmark_generated_labels.py')
    base = ['--root-path', 'r', '--out-dir', 'o']
    for flag, variant in (('--key-frame-only', 'keyframe'),
                          ('--no-box-frame', 'no-box-frame')):
        cfg = tool.label_config(tool.parse_args(base + [flag]))
        assert cfg == LabelConfig(**bench.VARIANTS[variant][1])
    cfg = tool.label_config(tool.parse_args(base + ['--key-frame-only']))
    assert (cfg.accumulate, cfg.fill_objects, cfg.ground_fill_radius,
            cfg.min_hit_ratio) == (False, False, 0.0, 0.0)
    assert tool.label_config(tool.parse_args(base)) == LabelConfig()
