"""Bad input gets a clear error naming the file; nothing is lost.

Each test damages its own copy of one tiny converted world (one scene, two
key frames) and checks the error message names the damaged file.
"""
import os
import os.path as osp
import re

import mmengine
import numpy as np
import pytest
from mmdet3d.registry import DATASETS
from mmdet3d.utils import register_all_modules
from mmengine.config import Config

import projects.occ_common  # noqa: F401  (registers)
from projects.occ_common.datasets.info_format import INFO_VERSION
from projects.occ_common.testing.tool_logs import run_create_data

register_all_modules(init_default_scope=True)
ONE_SCENE = pytest.mark.filterwarnings(
    'ignore:synthetic world with one scene')
REPO = osp.dirname(osp.dirname(osp.dirname(osp.dirname(__file__))))
TRAIN = 'nuscenes_occ_infos_train.pkl'


def create_data(*argv):
    return run_create_data('--version', 'v1.0-mini', *argv)


@pytest.fixture
def root(world_copy):
    """A private copy of the converted one-scene world to damage."""
    return world_copy


def dataset(root, fmt='surroundocc'):
    cfg = Config.fromfile(
        osp.join(REPO, 'configs', '_base_', 'datasets', f'{fmt}-nus.py'))
    ds_cfg = cfg.train_dataloader.dataset
    ds_cfg.data_root = root
    return DATASETS.build(ds_cfg)


def first_info(root):
    return mmengine.load(osp.join(root, TRAIN))['data_list'][0]


def test_missing_image(root):
    """Deleting CAM_BACK's image of sample 0: loading names that file."""
    path = osp.join(root, first_info(root)['images']['CAM_BACK']['img_path'])
    os.remove(path)
    with pytest.raises(FileNotFoundError,
                       match=re.escape(osp.basename(path))):
        dataset(root)[0]


@ONE_SCENE
def test_missing_sweep_in_loader_and_converter(root):
    """A deleted sweep: the pipeline names it, so does the converter."""
    rel = first_info(root)['lidar_sweeps'][3]['lidar_points']['lidar_path']
    os.remove(osp.join(root, rel))
    with pytest.raises(FileNotFoundError,
                       match=re.escape(osp.basename(rel))):
        dataset(root)[0]
    with pytest.raises(FileNotFoundError,
                       match='LiDAR sweep of sample .*' +
                       re.escape(osp.basename(rel))):
        create_data('--root-path', root, '--overwrite')


@ONE_SCENE
@pytest.mark.parametrize('key', ['occ_surroundocc_path', 'occ_occ3d_path',
                                 'pts_semantic_mask_path'])
def test_missing_label_files(root, key):
    """A deleted SurroundOcc / Occ3D / lidarseg label: the converter names
    it, and so does the loader of an info file made before the deletion."""
    path = osp.join(root, first_info(root)[key])
    os.remove(path)
    fmt = 'occ3d' if key == 'occ_occ3d_path' else 'surroundocc'
    with pytest.raises(FileNotFoundError,
                       match=re.escape(osp.basename(path))):
        dataset(root, fmt)[0]
    with pytest.raises(FileNotFoundError,
                       match=re.escape(osp.basename(path))):
        create_data('--root-path', root, '--overwrite')


def test_truncated_key_frame(root):
    """A key frame cut to 7 float32 (28 bytes, not a multiple of 20)."""
    path = osp.join(root, first_info(root)['lidar_points']['lidar_path'])
    np.fromfile(path, np.float32)[:7].tofile(path)
    with pytest.raises(ValueError,
                       match=re.escape(osp.basename(path)) + ' has 28 bytes'):
        dataset(root)[0]


@pytest.mark.parametrize('array, fmt, msg', [
    (np.zeros((5, 3), np.int64), 'surroundocc', r'\(M, 4\)'),
    (np.zeros((5, 4), np.float64), 'surroundocc', 'float64'),
    (dict(semantics=np.zeros((200, 200, 8), np.uint8),
          mask_lidar=np.zeros((200, 200, 16), np.uint8),
          mask_camera=np.zeros((200, 200, 16), np.uint8)), 'occ3d',
     r'\(200, 200, 8\)'),
    (dict(semantics=np.zeros((200, 200, 16), np.float32),
          mask_lidar=np.zeros((200, 200, 16), np.uint8),
          mask_camera=np.zeros((200, 200, 16), np.uint8)), 'occ3d',
     'float32'),
])
def test_label_of_wrong_shape_or_dtype(root, array, fmt, msg):
    """Replacing a label with a wrong-shape / wrong-dtype array."""
    path = osp.join(root, first_info(root)[f'occ_{fmt}_path'])
    with open(path, 'wb') as f:
        if isinstance(array, dict):
            np.savez(f, **array)
        else:
            np.save(f, array)
    name = re.escape(osp.basename(path))
    with pytest.raises(ValueError, match=name + '.*' + msg):
        dataset(root, fmt)[0]


def test_info_file_of_another_converter_version(root):
    """An info file with info_version 'mmdet3d-v2' is refused, naming the
    file, the found and the expected version; so is a file without
    data_list."""
    path = osp.join(root, TRAIN)
    infos = mmengine.load(path)
    infos['metainfo']['info_version'] = 'mmdet3d-v2'
    mmengine.dump(infos, path)
    with pytest.raises(ValueError,
                       match=f"{TRAIN}: info_version 'mmdet3d-v2'.*"
                       f"'{INFO_VERSION}'"):
        dataset(root)
    mmengine.dump(dict(infos=[]), path)
    with pytest.raises(ValueError, match=f'{TRAIN}: expected an info file'):
        dataset(root)
    os.remove(path)
    with pytest.raises(FileNotFoundError, match=TRAIN):
        dataset(root)


def test_zero_lidar_points_is_handled(root):
    """Key frame and its labels emptied: the sample still loads with only
    sweep points, all-zero depth maps (key frame only) and all-255 2D
    semantic maps."""
    info = first_info(root)
    np.zeros(0, np.float32).tofile(
        osp.join(root, info['lidar_points']['lidar_path']))
    np.zeros(0, np.uint8).tofile(
        osp.join(root, info['pts_semantic_mask_path']))
    sample = dataset(root)[0]
    ds = sample['data_samples']
    assert not ds.gt_depth.any() and (ds.gt_seg_2d == 255).all()
    assert (sample['inputs']['points'][:, 4] > 0).all()


def test_converter_never_overwrites(root):
    """A second run without --overwrite refuses and keeps the file; with
    --overwrite it rewrites all four splits."""
    path = osp.join(root, TRAIN)
    before = os.path.getmtime(path)
    with pytest.raises(FileExistsError, match='--overwrite'):
        create_data('--root-path', root)
    assert os.path.getmtime(path) == before
    with pytest.warns(UserWarning, match='one scene'):
        written = create_data('--root-path', root, '--overwrite')
    assert sorted(written) == ['train', 'val', 'val_night', 'val_rainy']


def _damage(path, how):
    """Empty, truncate to 40 % or flip one bit in the middle of a file."""
    with open(path, 'rb') as f:
        data = bytearray(f.read())
    if how == 'empty':
        data = b''
    elif how == 'truncated':
        data = data[:len(data) * 2 // 5]
    else:
        data[len(data) // 2] ^= 0x10
    with open(path, 'wb') as f:
        f.write(data)


@pytest.mark.parametrize('fmt, how, msg', [
    ('occ3d', 'empty', 'is empty'),
    ('occ3d', 'truncated', 'is truncated, corrupt'),
    ('occ3d', 'bitflip', 'is truncated, corrupt .*CRC'),
    ('surroundocc', 'empty', 'is empty'),
    ('surroundocc', 'truncated', 'is truncated or not a .npy'),
])
def test_damaged_label_file_names_it(root, fmt, how, msg):
    """Empty / cut / bit-flipped labels: ValueError naming the file.

    These raised BadZipFile, EOFError or zlib errors without a file name.
    A bit flip in an (uncompressed) .npz fails its member's CRC-32.
    """
    path = osp.join(root, first_info(root)[f'occ_{fmt}_path'])
    _damage(path, how)
    with pytest.raises(ValueError, match=re.escape(path) + ' ' + msg):
        dataset(root, fmt)[0]


def _image(root, cam='CAM_FRONT', sample=0):
    info = mmengine.load(osp.join(root, TRAIN))['data_list'][sample]
    return osp.join(root, info['images'][cam]['img_path'])


@pytest.mark.parametrize('how, msg', [
    ('empty', 'is empty \\(0 bytes\\)'),
    ('truncated', 'is a truncated JPEG .*no end-of-image marker'),
])
def test_empty_or_truncated_jpeg_names_it(root, how, msg):
    """OpenCV raised cv2.error on an empty JPEG and decoded one cut to
    40 % with its bottom rows black."""
    path = _image(root)
    _damage(path, how)
    with pytest.raises(ValueError, match=f'CAM_FRONT image of sample .* '
                       f'{msg}.*: {re.escape(path)}'):
        dataset(root)[0]


REAL_SAMPLE = osp.join(REPO, '..', 'shared', 'data', 'nuscenes_real_sample')


@pytest.mark.skipif(not osp.isdir(REAL_SAMPLE),
                    reason='../shared/data/nuscenes_real_sample is absent')
def test_real_jpegs_pass_the_completeness_check():
    """The six real nuScenes images end with their end-of-image marker."""
    from projects.occ_common.transforms.image_loading import \
        check_complete_image
    names = [n for n in os.listdir(REAL_SAMPLE) if n.endswith('.jpg')]
    assert len(names) == 6
    for name in names:
        with open(osp.join(REAL_SAMPLE, name), 'rb') as f:
            raw = f.read()
        check_complete_image(raw, name, name)
        with pytest.raises(ValueError, match='truncated JPEG'):
            check_complete_image(raw[:len(raw) * 2 // 5], name, name)


def _shrink_images(root, sample=0):
    """Resize every view of a sample to half its size (80x45)."""
    import cv2
    info = mmengine.load(osp.join(root, TRAIN))['data_list'][sample]
    for cam in info['images']:
        path = osp.join(root, info['images'][cam]['img_path'])
        img = cv2.imread(path)
        cv2.imwrite(path, cv2.resize(img, (80, 45)))


def test_image_of_another_size_than_its_calibration(root):
    """160x90 calibration, 80x45 images: an error naming both sizes;
    ``scale_calibration=True`` halves the focal lengths and principal
    point instead (pixel i covers [i, i + 1), so u' = u / 2)."""
    from projects.occ_common.transforms import LoadMultiViewImagesOcc
    _shrink_images(root)
    ds = dataset(root)
    info = ds.get_data_info(0)
    with pytest.raises(ValueError, match='CAM_FRONT: image .* is 80x45, '
                       'but its calibration \\(cam2img\\) is for 160x90'):
        LoadMultiViewImagesOcc()(dict(info))
    results = LoadMultiViewImagesOcc(scale_calibration=True)(dict(info))
    k = np.asarray(info['images']['CAM_FRONT']['cam2img'])[:3, :3]
    assert np.allclose(results['cam2img'][0][:3, :3],
                       np.diag([0.5, 0.5, 1.0]) @ k)
    assert results['img'][0].shape == (45, 80, 3)


def test_image_size_without_recorded_size_checks_the_principal_point(root):
    """An info file without height / width: the principal point (80, 45)
    of a 160x90 calibration lies at the corner of an 80x45 image."""
    from projects.occ_common.transforms import LoadMultiViewImagesOcc
    _shrink_images(root)
    info = dataset(root).get_data_info(0)
    for image in info['images'].values():
        del image['height'], image['width']
    with pytest.raises(ValueError, match='principal point .* is not in the '
                       'middle of the 80x45 image'):
        LoadMultiViewImagesOcc()(info)
