"""The loaders read regular files of sane sizes only, check what a label
file declares before numpy allocates or decompresses it, and decode
images as stored.

Before: an image path at a FIFO blocked forever, a LiDAR path at
``/dev/zero`` read until memory ran out, a ``labels.npz`` was decompressed
whole (4.6 GB from 4 MB) before its shape was checked, and a JPEG with an
EXIF orientation tag was decoded rotated. Loads that could block or eat
memory on a regression run in a forked child with a time and memory
limit, so this test fails instead of hanging.
"""
import io
import multiprocessing
import os
import resource
import tracemalloc

import cv2
import numpy as np
import pytest

from projects.occ_common.analysis.hostile_files import (write_exif_jpeg,
                                                        write_npz_bomb)
from projects.occ_common.fileio.input_files import MAX_INPUT_BYTES
from projects.occ_common.transforms import (LoadMultiViewImagesOcc,
                                            LoadOccPointsFromFile,
                                            LoadOccupancyGT)

K = [[2.0, 0.0, 12.0], [0.0, 2.0, 8.0], [0.0, 0.0, 1.0]]


def _view(path, **extra):
    return dict(img_path=str(path), cam2img=K, lidar2cam=np.eye(4).tolist(),
                cam2ego=np.eye(4).tolist(), **extra)


def _child(load, conn):
    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
    try:
        load()
        conn.send('loaded')
    except BaseException as err:  # noqa: BLE001 - MemoryError included
        conn.send(f'{type(err).__name__}: {err}')


def _outcome(load, seconds=30):
    """``load()`` in a forked child capped at 4 GB of address space:
    its error line, ``'loaded'``, or ``'blocked'`` after ``seconds``."""
    context = multiprocessing.get_context('fork')
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(load, send))
    child.start()
    child.join(seconds)
    if child.is_alive():
        child.kill()
        child.join()
        return 'blocked'
    return receive.recv() if receive.poll() else f'died {child.exitcode}'


def test_image_at_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / 'CAM_FRONT.jpg'
    os.mkfifo(fifo)
    load = LoadMultiViewImagesOcc()
    outcome = _outcome(
        lambda: load(dict(images=dict(CAM_FRONT=_view(fifo)), token='t')))
    assert outcome == (f'ValueError: CAM_FRONT image of sample t {fifo} is '
                       'a FIFO, not a regular file: reading it could block '
                       'or never end.')


def test_lidar_path_at_a_device_is_refused():
    load = LoadOccPointsFromFile(coord_type='LIDAR', load_dim=5, use_dim=5)
    outcome = _outcome(
        lambda: load(dict(lidar_points=dict(lidar_path='/dev/zero'))))
    assert outcome == ('ValueError: LiDAR key frame file /dev/zero is a '
                       'character device, not a regular file: reading it '
                       'could block or never end.')


def test_oversized_image_is_refused_before_it_is_read(tmp_path):
    """A sparse file one byte over the 128 MiB of an image."""
    path = tmp_path / 'big.jpg'
    with open(path, 'wb') as f:
        f.truncate(MAX_INPUT_BYTES['image'] + 1)
    with pytest.raises(ValueError, match=f'A image of sample t {path} is '
                       '134,217,729 bytes, more than the 134,217,728 such a '
                       'file may have'):
        LoadMultiViewImagesOcc()(dict(images=dict(A=_view(path)), token='t'))


def _peak_bytes(load, results):
    """``load(results)``, asserting that it allocates under 32 MB at its
    peak (numpy's allocations included) whether it returns or raises."""
    tracemalloc.start()
    try:
        return load(results)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < 32 << 20, f'{peak:,} bytes allocated'


def _npy(array_header, data: bytes) -> bytes:
    out = io.BytesIO()
    np.lib.format.write_array_header_1_0(out, array_header)
    return out.getvalue() + data


def test_npz_bomb_is_refused_before_it_is_decompressed(tmp_path):
    """semantics declares uint8 (2000, 2000, 80): 320 MB of zeros in a
    311 kB member. The declared shape is refused from the member's header,
    so at most a few MB are allocated (before: all 320 MB were
    decompressed, then the shape refused)."""
    path = tmp_path / 'labels.npz'
    grid = np.zeros((200, 200, 16), np.uint8)
    write_npz_bomb(str(path), 'semantics', (2000, 2000, 80),
                   [('mask_lidar', grid), ('mask_camera', grid)])
    assert path.stat().st_size < 1 << 20
    with pytest.raises(ValueError, match='semantics must be an integer '
                       r'array of shape \(200, 200, 16\), got uint8 '
                       r'\(2000, 2000, 80\)'):
        _peak_bytes(LoadOccupancyGT('occ3d'), dict(occ_path=str(path)))


def test_npy_declaring_a_huge_array_is_refused_before_allocating(tmp_path):
    """A SurroundOcc label whose header declares 50 M rows (1.6 GB of
    int64) followed by one row: refused from the header (before: numpy
    allocated the 1.6 GB, then found the data short)."""
    path = tmp_path / 'label.npy'
    path.write_bytes(_npy(dict(descr='<i8', fortran_order=False,
                               shape=(50_000_000, 4)),
                          np.zeros(4, np.int64).tobytes()))
    with pytest.raises(ValueError, match=r'is truncated or not a \.npy '
                       r'array: its header declares int64 \(50000000, '
                       r'4\) \(1,600,000,000 bytes\) but 32 bytes'):
        _peak_bytes(LoadOccupancyGT('surroundocc'), dict(occ_path=str(path)))


def test_exif_orientation_is_ignored(tmp_path):
    """A 24x16 JPEG tagged "rotate 90" (orientation 6) loads as stored,
    24 wide and 16 high, as its calibration (principal point (12, 8))
    describes it; OpenCV's default decode turned it to 16x24, and the
    principal-point check let that pass."""
    pixels = np.zeros((16, 24, 3), np.uint8)
    pixels[:, :12] = 255  # left half white
    path = tmp_path / 'front.jpg'
    write_exif_jpeg(str(path), pixels, orientation=6)
    assert cv2.imread(str(path)).shape == (24, 16, 3)  # what OpenCV does
    out = LoadMultiViewImagesOcc()(dict(images=dict(A=_view(path))))
    img = out['img'][0]
    assert img.shape == (16, 24, 3) and out['img_shape'] == (16, 24)
    np.testing.assert_array_equal(
        img, cv2.imread(str(path),
                        cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION))
    assert img[:, :10].min() > 200 and img[:, 14:].max() < 50
