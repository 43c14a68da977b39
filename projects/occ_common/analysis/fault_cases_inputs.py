"""Fault-matrix cases of a sample's inputs and the metrics' side files:
info files, LiDAR, images, labels, RayIoU's origins and GT cache, the
names of the files a tool writes (see :mod:`.fault_cases`)."""
import os
import os.path as osp
import pickle
import shutil
from typing import List

import numpy as np

from . import hostile_files as hostile
from .fault_cases import CLEAR, HANDLED, REAL_SAMPLE, Case, Silent, kept
from .fault_cases_files import REAL_INFO

#: A 200 x 200 x 16 grid (Occ3D's and SurroundOcc's).
_GRID = (200, 200, 16)


# -- info files ------------------------------------------------------------


def _info(edit):
    """An info file of the converter's layout (keys only), changed by
    ``edit``."""

    def made(folder, marker):
        from ..datasets.info_format import INFO_VERSION, REQUIRED_SAMPLE_KEYS
        entries = [{key: None for key in REQUIRED_SAMPLE_KEYS}
                   for _ in range(2)]
        for i, entry in enumerate(entries):
            entry['token'] = f'token{i}'
        infos = dict(metainfo=dict(info_version=INFO_VERSION),
                     data_list=entries)
        edit(infos)
        return _dump(infos, folder)

    return made


def _dump(infos, folder):
    path = osp.join(folder, 'infos.pkl')
    with open(path, 'wb') as f:
        pickle.dump(infos, f, protocol=2)
    return path


def _check_info(path):
    """What NuScenesOccDataset checks first."""
    from ..datasets.info_format import check_info_file
    from ..fileio import load_info_file
    return check_info_file(load_info_file(path), path)


def _sample(index: int, timestamp: float) -> dict:
    """A complete key frame of this library's layout (identity poses)."""
    from ..datasets.info_format import CAMERA_NAMES, REQUIRED_SAMPLE_KEYS
    eye = np.eye(4).tolist()
    entry = {key: None for key in REQUIRED_SAMPLE_KEYS}
    entry.update(
        sample_idx=index, token=f'token{index}', timestamp=timestamp,
        scene_token='scene', scene_name='scene-0001', is_rainy=False,
        is_night=False, ego2global=eye,
        lidar_points=dict(lidar_path=f'key{index}.bin', num_pts_feats=5,
                          lidar2ego=eye),
        lidar_sweeps=[dict(lidar_points=dict(lidar_path=f'sweep{index}.bin',
                                             sensor2lidar=eye),
                           timestamp=timestamp - 0.05)],
        images={cam: dict(img_path=f'{cam}{index}.jpg',
                          cam2img=[[800, 0, 800], [0, 800, 450], [0, 0, 1]],
                          lidar2cam=eye, cam2ego=eye)
                for cam in CAMERA_NAMES})
    return entry


def _frames(edit, which: int = 1):
    """Two key frames 0.5 s apart, the second linked to the first, frame
    ``which`` changed by ``edit`` (after the link was made)."""

    def made(folder, marker):
        from ..datasets.converters.key_frame_links import LINK_KEYS
        from ..datasets.info_format import INFO_VERSION
        first, second = _sample(0, 100.0), _sample(1, 100.5)
        first['prev_key_frame'] = None
        second['prev_key_frame'] = {k: first[k] for k in LINK_KEYS}
        edit((first, second)[which])
        return _dump(dict(metainfo=dict(info_version=INFO_VERSION),
                          data_list=[first, second]), folder)

    return made


def _build(path):
    """NuScenesOccDataset over two frames of the info file."""
    from ..datasets.nuscenes_occ_dataset import NuScenesOccDataset
    return NuScenesOccDataset(data_root=osp.dirname(path),
                              ann_file='infos.pkl', test_mode=True,
                              num_frames=2)


def _dataset(path):
    """:func:`_build`: it must refuse what the edit broke (accepting it is
    silent)."""
    _build(path)
    raise Silent('the dataset accepted it')


# -- files of a sample -----------------------------------------------------


def _points(layout):
    """A LiDAR key frame of nuScenes points written as ``layout``."""
    rows = np.array([[12.345, -3.21, 0.875, 17, 3], [-40.5, 7.1, -1.6, 2, 31]])

    def made(folder, marker):
        path = osp.join(folder, 'key.pcd.bin')
        if layout == 'float64':
            rows.tofile(path)
        elif layout == '4 values a point':
            np.tile(rows, (3, 1))[:5, :4].astype(np.float32).tofile(path)
        else:  # all NaN
            np.full((2, 5), np.nan, np.float32).tofile(path)
        return path

    return made


def _load_points(path):
    """LoadOccPointsFromFile; an all-NaN frame must be dropped with a
    warning naming the file (else a silent drop)."""
    import warnings

    import projects.occ_common.transforms  # noqa: F401  (registers)
    from ..transforms.points_loading import LoadOccPointsFromFile
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        points = load(dict(lidar_points=dict(lidar_path=path)))['points']
    if not any(path in str(w.message) for w in caught) and len(points) < 5:
        raise Silent('points dropped without a word')
    return points


def _device(folder, marker):
    return '/dev/zero'


def _fifo(folder, marker):
    path = osp.join(folder, 'CAM_FRONT.jpg')
    os.mkfifo(path)
    return path


def _load_image(path):
    """LoadMultiViewImagesOcc of one view, the calibration for a 24 x 16
    image; the pixels must be those stored (a rotated decode is silent)."""
    import cv2

    from ..transforms.image_loading import LoadMultiViewImagesOcc
    view = dict(img_path=path, cam2img=[[2, 0, 12], [0, 2, 8], [0, 0, 1]],
                lidar2cam=np.eye(4), cam2ego=np.eye(4))
    img = LoadMultiViewImagesOcc()(dict(images=dict(CAM_FRONT=view),
                                        token='t'))['img'][0]
    stored = cv2.imread(path, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    if img.shape != stored.shape or not np.array_equal(img, stored):
        raise Silent(f'decoded as {img.shape}, stored as {stored.shape}')
    return img


def _exif_jpeg(folder, marker):
    pixels = np.zeros((16, 24, 3), np.uint8)
    pixels[:, :12] = 255
    return hostile.write_exif_jpeg(osp.join(folder, 'CAM_FRONT.jpg'),
                                   pixels)


def _bool_semantics(folder, marker):
    path = osp.join(folder, 'labels.npz')
    grid = np.zeros(_GRID, np.uint8)
    np.savez(path, semantics=grid.astype(bool), mask_lidar=grid,
             mask_camera=grid)
    return path


def _npz_bomb(folder, marker):
    """semantics declares (2000, 2000, 80) uint8: 320 MB of zeros in
    311 kB."""
    grid = np.zeros(_GRID, np.uint8)
    return hostile.write_npz_bomb(
        osp.join(folder, 'labels.npz'), 'semantics', (2000, 2000, 80),
        [('mask_lidar', grid), ('mask_camera', grid)])


def _load_occ3d(path):
    import projects.occ_common.transforms  # noqa: F401  (registers)
    from ..transforms.loading import LoadOccupancyGT
    return LoadOccupancyGT('occ3d')(dict(occ_path=path))


# -- RayIoU's side files ---------------------------------------------------


def _ray_infos(folder, marker):
    """A scene of two frames, egos at x = 0 and 0.2 m."""
    from ..datasets.info_format import INFO_VERSION, REQUIRED_SAMPLE_KEYS
    entries = []
    for i, x in enumerate((0.0, 0.2)):
        ego2global = np.eye(4)
        ego2global[0, 3] = x
        entry = {key: None for key in REQUIRED_SAMPLE_KEYS}
        entry.update(sample_idx=i, token=f't{i}', timestamp=float(i),
                     scene_token='s', ego2global=ego2global.tolist(),
                     lidar_points=dict(lidar2ego=np.eye(4).tolist()))
        entries.append(entry)
    return _dump(dict(metainfo=dict(info_version=INFO_VERSION),
                      data_list=entries), folder)


def _ray_metric(**kwargs):
    from ..evaluation.ray_iou_metric import RayIoUMetric
    return RayIoUMetric(pc_range=(0, 0, 0, 1.2, 1.2, 1.2), voxel_size=0.4,
                        **kwargs)


def _ray_sample(gt=4, **meta):
    grid = np.full((3, 3, 3), 4, np.uint8)
    return dict(pred_occ=grid, gt_occ=np.full((3, 3, 3), gt, np.uint8),
                **meta)


def _origins_of_another_root(path):
    """t0 of the evaluated dataset has another ego pose than t0 of the
    metric's info file (the dataloader's root was overridden)."""
    metric = _ray_metric(ann_file=osp.basename(path),
                         data_root=osp.dirname(path))
    moved = np.eye(4)
    moved[1, 3] = 5.0
    metric.process({}, [_ray_sample(token='t0', timestamp=0.0,
                                    ego2global=moved)])
    raise Silent('scored with the origins of another dataset')


def _cache_folder(folder, marker):
    """A GT cache in which sample a's file holds sample b's hits."""
    cache = osp.join(folder, 'cache')
    metric = _ray_metric(gt_cache_dir=cache)
    metric.process({}, [_ray_sample(4, token='a', ray_origins=[[.6] * 3])])
    metric.process({}, [_ray_sample(9, token='b', ray_origins=[[.6] * 3])])
    first, second = sorted(os.listdir(cache),
                           key=lambda n: os.stat(osp.join(cache, n)).st_mtime)
    shutil.copy(osp.join(cache, second), osp.join(cache, first))
    return cache


def _cached_counts(path):
    """Sample a again: its counts must be a's (a full grid of its class
    4: every ray a true positive), not b's."""
    metric = _ray_metric(gt_cache_dir=path)
    metric.process({}, [_ray_sample(4, token='a', ray_origins=[[.6] * 3])])
    counts = metric.results[0]
    if counts['tp'][0, 4] != counts['gt'][4] or counts['gt'][4] == 0:
        raise Silent('the replaced cache file was used')


# -- names from files ------------------------------------------------------


def _victim_beside(folder):
    victim = osp.join(folder, 'victim_info.pkl')
    with open(victim, 'w') as f:
        f.write('keep me')
    return victim


def _traversing_token(folder, marker):
    """The real sample's mmdet3d info file, its token ``../victim``, and
    a file ``victim_info.pkl`` beside the demo's temporary folder."""
    from ..fileio import load_info_file
    infos = load_info_file(REAL_INFO)
    infos['data_list'][0]['token'] = '../victim'
    work = osp.join(folder, 'tmp')
    os.makedirs(work)
    _victim_beside(folder)
    with open(osp.join(folder, 'infos.pkl'), 'wb') as f:
        pickle.dump(infos, f)
    return osp.join(folder, 'infos.pkl')


def _convert_sample(path):
    """The demo's (and export_onnx.py --verify's) conversion of an mmdet3d
    sample into ``<tmp>/<token>_info.pkl``."""
    from ..datasets.single_sample import sample_info_file
    folder = osp.dirname(path)
    return sample_info_file(path, REAL_SAMPLE, osp.join(folder, 'tmp'))


def _prediction_token(folder, marker):
    _victim_beside(folder)
    return osp.join(folder, 'predictions')


def _format_only(path):
    """OccupancyMetric(format_only) of a sample whose token is
    ``../victim_info.pkl`` (tools/test.py --format-only)."""
    from ..evaluation.occupancy_metric import OccupancyMetric
    metric = OccupancyMetric(convention='occ3d', format_only=True,
                             submission_prefix=path)
    metric.process({}, [dict(token='../victim_info', sample_idx=0,
                             pred_occ=np.zeros(_GRID, np.uint8))])


def _victim(path) -> List[str]:
    return [osp.join(osp.dirname(path), 'victim_info.pkl')]


#: A sample's inputs and the metrics' side files.
INPUT_CASES: List[Case] = [
    *(Case(f'LiDAR key frame of {layout}', expected, _points(layout),
           _load_points, guards=('ring column checked', ))
      for layout, expected in (('float64', CLEAR), ('4 values a point',
                                                    CLEAR),
                               ('all NaN', HANDLED))),
    Case('LiDAR path at a device file (/dev/zero)', CLEAR, _device,
         _load_points, memory_mb=1024, timeout=60,
         guards=('regular files only', )),
    Case('image path at a FIFO: LoadMultiViewImagesOcc', CLEAR, _fifo,
         _load_image, timeout=20, guards=('regular files only', )),
    Case('JPEG with an EXIF orientation tag: LoadMultiViewImagesOcc',
         HANDLED, _exif_jpeg, _load_image, guards=('EXIF ignored', )),
    Case('info file listing a sample twice', CLEAR,
         _info(lambda i: i['data_list'].append(i['data_list'][0])),
         _check_info, guards=('info file checked', )),
    Case('info file with a sample that is not a dict', CLEAR,
         _info(lambda i: i['data_list'].append(['token2'])), _check_info),
    Case('info file whose metainfo is a list', CLEAR,
         _info(lambda i: i.update(metainfo=list(i['metainfo'].items()))),
         _check_info),
    Case('two valid key frames: NuScenesOccDataset', HANDLED,
         _frames(lambda s: None), _build),
    Case('NaN timestamp: NuScenesOccDataset', CLEAR,
         _frames(lambda s: s.update(timestamp=float('nan')), which=0),
         _dataset,
         guards=('finite timestamps', )),
    Case('sweep time-stamped after its key frame: NuScenesOccDataset',
         CLEAR,
         _frames(lambda s: s['lidar_sweeps'][0].update(timestamp=101.0)),
         _dataset, guards=('sweeps before key frame', )),
    Case('all-zero sensor2lidar: NuScenesOccDataset', CLEAR,
         _frames(lambda s: s['lidar_sweeps'][0]['lidar_points'].update(
             sensor2lidar=np.zeros((4, 4)).tolist())), _dataset,
         guards=('rigid transforms', )),
    Case('previous key frame from the future: NuScenesOccDataset', CLEAR,
         _frames(lambda s: s['prev_key_frame'].update(timestamp=100.6)),
         _dataset, guards=('previous frames checked', )),
    Case('boolean Occ3D semantics', CLEAR, _bool_semantics, _load_occ3d),
    Case('labels.npz declaring 320 MB of zeros in 311 kB', CLEAR, _npz_bomb,
         _load_occ3d, memory_mb=160, guards=('label headers checked', )),
    Case('RayIoU origins of another data root: OccRayIoUMetric', CLEAR,
         _ray_infos, _origins_of_another_root,
         guards=('ray origins matched', )),
    Case('RayIoU GT cache file replaced by another sample\'s', HANDLED,
         _cache_folder, _cached_counts, guards=('ray cache verified', )),
    Case('prediction of a sample whose token is ../victim_info: '
         'tools/test.py --format-only', CLEAR, _prediction_token,
         kept(_format_only, _victim), names=lambda path: ['../victim_info'],
         guards=('prediction name checked', )),
]
if osp.isfile(REAL_INFO):
    INPUT_CASES.append(
        Case('mmdet3d sample whose token is ../victim: demo/occ_demo.py and '
             'export_onnx.py --verify', CLEAR, _traversing_token,
             kept(_convert_sample, _victim),
             guards=('sample token checked', )))

__all__ = ['INPUT_CASES']
