"""End to end: tiny synthetic world -> tools/create_data.py -> dataset.

One two-scene world (a clear day, a rainy night; 2 key frames each, 160x90
images) is generated and converted once for the module; every test then
checks real content against the generator's own ground truth
(``synthetic_gt/``: the world's boxes and the rendered class of every
pixel).
"""
import importlib.util
import json
import os
import os.path as osp

import cv2
import mmengine
import numpy as np
import pytest
from mmdet3d.registry import DATASETS, TRANSFORMS
from mmdet3d.utils import register_all_modules
from mmengine.config import Config

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.synthetic import world_from_dict
from projects.occ_common.synthetic.camera_classes import rendered_classes
from projects.occ_common.testing.tiny_world import make_tiny_world

register_all_modules(init_default_scope=True)
REPO = osp.dirname(osp.dirname(osp.dirname(osp.dirname(__file__))))
CONFIGS = osp.join(REPO, 'configs', '_base_', 'datasets')


def run_create_data(argv):
    """Run tools/create_data.py's main() in this process."""
    spec = importlib.util.spec_from_file_location(
        'create_data', osp.join(REPO, 'tools', 'create_data.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main(argv)


@pytest.fixture(scope='module')
def root(tmp_path_factory):
    root = make_tiny_world(
        str(tmp_path_factory.mktemp('nus_world')), num_scenes=2)
    run_create_data(
        ['nuscenes', '--root-path', root, '--version', 'v1.0-mini'])
    return root


def build_dataset(root, fmt='surroundocc', split='train', pipeline=None):
    """The dataset of a base config, pointed at ``root``."""
    cfg = Config.fromfile(osp.join(CONFIGS, f'{fmt}-nus.py'))
    loader = cfg.train_dataloader if split == 'train' else cfg.val_dataloader
    ds_cfg = loader.dataset
    ds_cfg.data_root = root
    ds_cfg.ann_file = f'nuscenes_occ_infos_{split}.pkl'
    if pipeline is not None:
        ds_cfg.pipeline = pipeline
    return DATASETS.build(ds_cfg)


def compose(*steps):
    transforms = [TRANSFORMS.build(step) for step in steps]

    def run(results):
        for t in transforms:
            results = t(results)
        return results

    return run


LOAD_KEY_FRAME = [
    dict(type='LoadOccPointsFromFile', coord_type='LIDAR', load_dim=5,
         use_dim=5),
    dict(type='LoadLidarSegLabels'),
]


def test_info_files(root):
    """Scene 1 (clear) is train, scene 2 (rainy night) val: 2 samples each,
    both in val_rainy and val_night; every sample links 10 sweeps with
    timestamps 0.05 s apart and 6 cameras; the version check passes."""
    infos = {
        split: mmengine.load(osp.join(root, f'nuscenes_occ_infos_{split}.pkl'))
        for split in ('train', 'val', 'val_rainy', 'val_night')
    }
    assert [len(v['data_list']) for v in infos.values()] == [2, 2, 2, 2]
    train, val = infos['train']['data_list'], infos['val']['data_list']
    assert {e['scene_name'] for e in train} == {'scene-0001'}
    assert not any(e['is_rainy'] or e['is_night'] for e in train)
    assert all(e['is_rainy'] and e['is_night'] for e in val)
    assert infos['val']['metainfo']['synthetic'] is True
    for entry in train + val:
        sweeps = entry['lidar_sweeps']
        assert len(sweeps) == 10 and len(entry['images']) == 6
        lags = [entry['timestamp'] - s['timestamp'] for s in sweeps]
        np.testing.assert_allclose(lags, 0.05 * np.arange(1, 11), atol=1e-6)
        for path in (entry['occ_surroundocc_path'], entry['occ_occ3d_path'],
                     entry['pts_semantic_mask_path']):
            assert osp.isfile(osp.join(root, path))
    assert len(build_dataset(root, 'occ3d', 'val')) == 2


def test_points_land_on_their_rendered_class(root):
    """Key-frame points projected with lidar2img hit pixels rendered with
    their lidarseg class: for each view, the 2D semantic map (nearest
    labelled point per pixel) agrees with the rendered class map on most
    pixels (the LiDAR sits 1.84 m up, the cameras ~1.5 m, so a few points
    are hidden from the camera behind nearer objects)."""
    dataset = build_dataset(root, pipeline=[])
    run = compose(*LOAD_KEY_FRAME, dict(type='LoadMultiViewImagesOcc'),
                  dict(type='PointsToSemanticMaps'))
    hits = agree = 0
    for idx in range(len(dataset)):
        results = run(dataset.get_data_info(idx))
        for view, path in enumerate(results['img_path']):
            seg = results['gt_seg_2d'][view]
            render = rendered_classes(root, path)
            hit = seg != 255
            hits += hit.sum()
            agree += (seg[hit] == render[hit]).sum()
    assert hits > 300
    assert agree / hits > 0.9, (agree, hits)  # measured 0.94


def test_occupancy_formats_agree(root):
    """Every occupied Occ3D voxel (ego frame, 0.4 m), moved to the LiDAR
    frame with inv(lidar2ego), falls in a SurroundOcc voxel (0.5 m) whose
    3x3x3 neighbourhood holds the same class, for almost all voxels inside
    both ranges; for the classes alone the histograms agree too."""
    dataset = build_dataset(root, pipeline=[])
    load_s = TRANSFORMS.build(dict(type='LoadOccupancyGT',
                                   occ_format='surroundocc'))
    load_o = TRANSFORMS.build(dict(type='LoadOccupancyGT',
                                   occ_format='occ3d'))
    checked = matched = 0
    for idx in range(len(dataset)):
        info = dataset.get_data_info(idx)
        sur = load_s(dict(occ_path=info['occ_surroundocc_path']))['gt_occ']
        occ = load_o(dict(occ_path=info['occ_occ3d_path']))['gt_occ']
        ijk = np.argwhere((occ >= 1) & (occ <= 16))
        centres = np.array([-40.0, -40.0, -1.0]) + (ijk + 0.5) * 0.4
        ego2lidar = np.linalg.inv(info['lidar2ego'])
        lidar = centres @ ego2lidar[:3, :3].T + ego2lidar[:3, 3]
        sidx = np.floor((lidar - [-50.0, -50.0, -5.0]) / 0.5).astype(int)
        inside = np.all((sidx >= 1) & (sidx < np.array([199, 199, 15])), 1)
        padded = np.pad(sur, 1, constant_values=0)
        labels = occ[tuple(ijk[inside].T)]
        near = np.zeros(len(labels), bool)
        for d in np.ndindex(3, 3, 3):
            s = sidx[inside] + np.array(d)  # +1 pad, -1 offset cancel
            near |= padded[tuple(s.T)] == labels
        checked += len(labels)
        matched += near.sum()
    assert checked > 1000
    assert matched / checked > 0.99, (matched, checked)


def _static_surface_distance(world, xyz_global):
    """Distance from each point to the nearest surface of a static box."""
    boxes = world.boxes
    static = np.flatnonzero(np.all(boxes.velocity == 0, axis=1))
    best = np.full(len(xyz_global), np.inf)
    for b in static:
        local = boxes.to_local(xyz_global, np.full(len(xyz_global), b), 0.0)
        q = np.abs(local) - boxes.size[b] / 2
        outside = np.linalg.norm(np.maximum(q, 0), axis=1)
        dist = np.abs(outside + np.minimum(q.max(axis=1), 0))
        best = np.minimum(best, dist)
    return best


def test_sweeps_line_up_in_key_frame(root):
    """The 10 merged sweeps are in the key frame's LiDAR coordinates: mapped
    to the global frame with the key frame's pose, their points lie on the
    surfaces of static boxes (buildings, parked cars, trees; within 3 cm,
    the generator adds 1 cm range noise) as often as the key frame's own
    points do (8-9 % here: a bus passing on the left hides the buildings
    behind it; over 6 % is asserted so that the shares below count hundreds
    of points). Read without ego-motion compensation (each
    sweep as if it were the key frame, the car moves ~5 m/s) the walls
    facing the motion smear and that share drops below half."""
    dataset = build_dataset(root, pipeline=[])
    merge = compose(LOAD_KEY_FRAME[0],
                    dict(type='LoadOccPointsFromMultiSweeps', sweeps_num=10,
                         test_mode=True))
    read = compose(LOAD_KEY_FRAME[0])
    info = dataset.get_data_info(1)  # scene-0001, second key frame
    with open(osp.join(root, 'synthetic_gt', 'worlds',
                       f'{info["scene_name"]}.json')) as f:
        world = world_from_dict(json.load(f))
    lidar2global = info['ego2global'] @ info['lidar2ego']

    def on_static_share(xyz):
        glob = xyz @ lidar2global[:3, :3].T + lidar2global[:3, 3]
        return (_static_surface_distance(world, glob) < 0.03).mean()

    pts = merge(dict(info))['points'].tensor.numpy()
    assert len(pts) > 10 * 1000 and (pts[:, 4] > 0).sum() > 9 * 1000
    key_share = on_static_share(pts[pts[:, 4] == 0, :3])
    sweep_share = on_static_share(pts[pts[:, 4] > 0, :3])
    naive = np.concatenate([
        read(dict(lidar_points=dict(lidar_path=s['lidar_points']
                                    ['lidar_path'])))['points'].tensor.numpy()
        for s in info['lidar_sweeps']
    ])
    assert key_share > 0.06  # measured 0.082; sweeps 0.089, naive 0.018
    assert sweep_share > 0.8 * key_share
    assert on_static_share(naive[:, :3]) < 0.5 * key_share


def _inverse_warp(source, aug_matrix, out_shape, fill):
    """Nearest-neighbour warp of ``source`` by a 4x4 img_aug_matrix."""
    height, width = out_shape
    rows, cols = np.mgrid[0:height, 0:width]
    mat = np.eye(3)
    mat[:2, :2], mat[:2, 2] = aug_matrix[:2, :2], aug_matrix[:2, 2]
    pix = np.stack([cols + 0.5, rows + 0.5, np.ones_like(cols)], -1)
    src = pix.reshape(-1, 3) @ np.linalg.inv(mat).T
    col, row = np.floor(src[:, 0]).astype(int), np.floor(src[:, 1]).astype(int)
    inside = (col >= 0) & (col < source.shape[1]) & (row >= 0) & (
        row < source.shape[0])
    out = np.full((height * width, ) + source.shape[2:], fill, source.dtype)
    out[inside] = source[row[inside], col[inside]]
    return out.reshape((height, width) + source.shape[2:]), inside.reshape(
        height, width)


def test_image_aug_keeps_depth_maps_on_the_image(root):
    """Random resize / crop / flip / rotate (seeded) of 160x90 views to
    112x64: (1) the augmented image is the source warped by img_aug_matrix
    (mean |difference| to a nearest-neighbour warp of the source below 10
    grey levels, measured 3-6), while the matrix of a flipped view with the
    flip undone misses by over twice that in every flipped view (measured
    2.9-8x: a view down the road is nearly mirror-symmetric) and by over 4
    times in total (measured 5.9x);
    (2) the pixels of the sparse depth maps show, in the equally warped
    render, the class of the LiDAR point that put the depth there, for over
    85 % of the depth pixels (measured 92 %; 94 % without augmentation)."""
    np.random.seed(3)
    dataset = build_dataset(root, pipeline=[])
    run = compose(*LOAD_KEY_FRAME, dict(type='LoadMultiViewImagesOcc'),
                  dict(type='MultiViewImageAug', final_size=(64, 112),
                       resize_range=(0.9, 1.2), rot_range=(-10, 10),
                       flip_prob=0.5),
                  dict(type='PointsToDepthMaps'),
                  dict(type='PointsToSemanticMaps'))
    load_img = TRANSFORMS.build(dict(type='LoadMultiViewImagesOcc'))
    hits = agree = 0
    good_sum, bad_sum = [], []
    for idx in range(len(dataset)):
        results = run(dataset.get_data_info(idx))
        sources = load_img(dataset.get_data_info(idx))['img']
        for view, path in enumerate(results['img_path']):
            mat = results['img_aug_matrix'][view]
            img = results['img'][view].astype(float)
            warped, inside = _inverse_warp(sources[view].astype(float), mat,
                                           (64, 112), 0.0)
            # Skip a 2-pixel border where interpolation mixes in the fill.
            core = cv2.erode(inside.astype(np.uint8), np.ones((5, 5))) > 0
            good = np.abs(img - warped)[core].mean()
            assert good < 10
            if results['img_aug_params'][view]['flip']:
                wrong = mat.copy()
                wrong[0] = -wrong[0] + np.array([0, 0, 112, 0])
                bad, _ = _inverse_warp(sources[view].astype(float), wrong,
                                       (64, 112), 0.0)
                bad = np.abs(img - bad)[core].mean()
                assert bad > 2 * good
                good_sum.append(good)
                bad_sum.append(bad)
            render, _ = _inverse_warp(rendered_classes(root, path), mat,
                                      (64, 112), 255)
            depth = results['gt_depth'][view] > 0
            seg = results['gt_seg_2d'][view]
            hit = depth & (seg != 255)
            hits += hit.sum()
            agree += (seg[hit] == render[hit]).sum()
    assert len(good_sum) > 0 and hits > 300
    assert sum(bad_sum) > 4 * sum(good_sum)
    assert agree / hits > 0.85, (agree, hits)  # measured 0.92


@pytest.mark.parametrize('fmt', ['surroundocc', 'occ3d'])
def test_config_pipelines_batch(root, fmt):
    """The base configs' train pipelines run on the world and two samples
    batch through Det3DDataPreprocessor to imgs (2, 6, 3, 256, 704); the
    Occ3D pipeline works in the ego frame (lidar2ego = I before the BEV
    augmentation, so its inverse bda_matrix after it, whichever flip was
    drawn; ``free`` = 17 present), the SurroundOcc one in the LiDAR frame
    (``empty`` = 0)."""
    from mmdet3d.models.data_preprocessors import Det3DDataPreprocessor
    from mmengine.dataset import pseudo_collate
    dataset = build_dataset(root, fmt)
    batch = pseudo_collate([dataset[0], dataset[1]])
    out = Det3DDataPreprocessor(
        mean=[123.675, 116.28, 103.53], std=[58.395, 57.12, 57.375],
        bgr_to_rgb=True)(batch, training=True)
    assert out['inputs']['imgs'].shape == (2, 6, 3, 256, 704)
    sample = out['data_samples'][0]
    assert sample.gt_occ.shape == (200, 200, 16)
    assert sample.gt_depth.shape == (6, 256, 704)
    assert (sample.gt_depth > 0).sum() > 100
    assert sample.metainfo['coord_frame'] == dict(
        surroundocc='lidar', occ3d='ego')[fmt]
    if fmt == 'occ3d':
        np.testing.assert_allclose(
            sample.metainfo['lidar2ego'] @ sample.metainfo['bda_matrix'],
            np.eye(4), atol=1e-6)
        assert (sample.gt_occ == 17).any() and sample.mask_camera.any()
    else:
        assert (sample.gt_occ == 0).sum() > 0.5 * sample.gt_occ.numel()
    points = out['inputs']['points'][0]
    lo, hi = dataset.metainfo['point_cloud_range'][:3], dataset.metainfo[
        'point_cloud_range'][3:]
    assert (points[:, :3].numpy() >= lo).all()
    assert (points[:, :3].numpy() <= hi).all()


def test_dataset_arguments(root, tmp_path):
    """load_interval=2 keeps 1 of 2 samples; an Occ3D dataset in the LiDAR
    frame is refused; without labels of the format, training drops the
    sample (filter_empty_gt) and test mode keeps it; metainfo classes
    follow the format (17 / 18 names) and a list of another length is
    refused."""
    cfg = dict(type='NuScenesOccDataset', data_root=root,
               ann_file='nuscenes_occ_infos_val.pkl')
    assert len(DATASETS.build(dict(cfg, load_interval=2))) == 1
    with pytest.raises(ValueError, match="coord_frame='ego'"):
        DATASETS.build(dict(cfg, occ_format='occ3d', coord_frame='lidar'))
    infos = mmengine.load(osp.join(root, 'nuscenes_occ_infos_val.pkl'))
    infos['data_list'][0]['occ_occ3d_path'] = None
    mmengine.dump(infos, str(tmp_path / 'partial.pkl'))
    partial = dict(cfg, ann_file=str(tmp_path / 'partial.pkl'),
                   occ_format='occ3d')
    train = DATASETS.build(partial)
    assert len(train) == 1 and len(train.metainfo['classes']) == 18
    assert train.metainfo['coord_frame'] == 'ego'
    assert len(DATASETS.build(dict(partial, test_mode=True))) == 2
    assert len(DATASETS.build(cfg).metainfo['classes']) == 17
    with pytest.raises(ValueError, match='18 classes'):
        DATASETS.build(dict(cfg, occ_format='occ3d',
                            metainfo=dict(classes=['a', 'b'])))


@pytest.mark.filterwarnings('ignore:synthetic world with one scene')
@pytest.mark.parametrize('fmt', ['surroundocc', 'occ3d'])
def test_config_pipelines_drop_ego_returns(world_copy, fmt):
    """Three returns off the car (the sensor, the bonnet, a mirror; ego
    (0.985, 0, 1.94), (3.485, 0, 0.94), (1.485, -1.05, 0.84)) added to
    the key frame and to its newest sweep of a one-scene world (which has
    no ego returns of its own): the base test pipeline gives exactly the
    points it gave before, and no key-frame point lies in the ego box.
    (Sweep points may: the ground the car has since driven onto.) The old
    pipeline kept all three key-frame returns and the sweep's bonnet and
    mirror returns (its remove_close is a 1 m sphere)."""
    from projects.occ_common.transforms.ego_points import in_ego_box
    info = mmengine.load(
        osp.join(world_copy, 'nuscenes_occ_infos_val.pkl'))['data_list'][0]

    def points():
        sample = build_dataset(world_copy, fmt, split='val')[0]
        return (sample['inputs']['points'].numpy(),
                sample['data_samples'].metainfo['lidar2ego'])

    before, _ = points()
    car = np.array([[0, 0, 0.1, 1, 0], [0, 2.5, -0.9, 1, 0],
                    [1.05, 0.5, -1.0, 1, 0]], np.float32)
    for rel in (info['lidar_points']['lidar_path'],
                info['lidar_sweeps'][0]['lidar_points']['lidar_path']):
        path = osp.join(world_copy, rel)
        np.concatenate([np.fromfile(path, np.float32), car.ravel()]).tofile(
            path)
    labels = osp.join(world_copy, info['pts_semantic_mask_path'])
    np.concatenate([np.fromfile(labels, np.uint8),
                    np.zeros(3, np.uint8)]).tofile(labels)
    after, lidar2ego = points()
    np.testing.assert_array_equal(after, before)
    key = after[after[:, 4] == 0, :3]
    # The working frame -> ego: lidar2ego (the identity for Occ3D).
    assert not in_ego_box(key, lidar2ego,
                          (-0.9, -1.1, -0.5, 3.7, 1.1, 2.2)).any()


@pytest.mark.filterwarnings('ignore:synthetic world with one scene')
@pytest.mark.parametrize('fmt', ['surroundocc', 'occ3d'])
def test_seg2d_targets_with_and_without_lidarseg(world_copy, fmt):
    """The dataset bases' plain pipelines (OccCylindrical's) never read
    lidarseg and make no 2-D semantic maps; the ``*_seg2d`` ones (SDG-OCC's)
    take them from lidarseg where the info has it, and from the occupancy
    labels after the lidarseg files and paths are gone. The two maps agree
    on most pixels both label (the voxel labels are the lidarseg labels
    voxelised). The old base pipeline raised without lidarseg."""
    cfg = Config.fromfile(osp.join(CONFIGS, f'{fmt}-nus.py'))
    plain = [t.type for t in cfg.test_pipeline]
    assert 'LoadLidarSegLabels' not in plain
    assert 'PointsToSemanticMaps' not in plain
    ann = osp.join(world_copy, 'nuscenes_occ_infos_val.pkl')

    def sample(pipeline):
        out = build_dataset(world_copy, fmt, 'val', pipeline)[0]
        return out['data_samples']

    with_lidarseg = sample(cfg.test_pipeline_seg2d)
    assert with_lidarseg.metainfo['seg_2d_source'] == 'lidarseg'
    infos = mmengine.load(ann)
    for info in infos['data_list']:
        os.remove(osp.join(world_copy, info['pts_semantic_mask_path']))
        info['pts_semantic_mask_path'] = None
    mmengine.dump(infos, ann)
    assert 'gt_seg_2d' not in sample(cfg.test_pipeline)
    without = sample(cfg.test_pipeline_seg2d)
    assert without.metainfo['seg_2d_source'] == 'occupancy'
    old, new = (s.gt_seg_2d.numpy() for s in (with_lidarseg, without))
    both = (old != 255) & (new != 255)
    # Measured: of the 1,319 pixels lidarseg labels, 1,194 (SurroundOcc) /
    # 1,092 (Occ3D) are labelled from occupancy too (no other), 96.6 % /
    # 97.1 % of them alike.
    assert both.sum() > 0.5 * (old != 255).sum()
    assert (old[both] == new[both]).mean() > 0.9
