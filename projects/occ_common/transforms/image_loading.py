"""Loading of the multi-view camera images and their calibration.

Every check names the file and what was expected: a path that is no
regular file or too large, an empty, truncated or undecodable image, a
non-finite matrix, or an image whose size is not the one its calibration
belongs to. EXIF orientation tags are ignored (:func:`decode_flag`).
"""
from typing import Optional, Sequence

import mmcv
import numpy as np
from mmcv.transforms import BaseTransform
from mmdet3d.registry import TRANSFORMS

from ..datasets.info_format import as_matrix
from .frames import refresh_lidar2img
from .loading import read_bytes


def _pad44(mat, where: str) -> np.ndarray:
    """A finite 3x3 or 4x4 matrix as 4x4 float64."""
    mat = as_matrix(mat, [(3, 3), (4, 4)], where)
    out = np.eye(4)
    out[:mat.shape[0], :mat.shape[1]] = mat
    return out


def check_complete_image(raw: bytes, path: str, what: str) -> None:
    """Refuse an empty file and a JPEG / PNG cut short.

    OpenCV decodes a truncated JPEG with its missing rows black (and only
    warns); a complete JPEG ends its last scan (``FFDA``) with the
    end-of-image marker ``FFD9``, a complete PNG with its ``IEND`` chunk.

    Args:
        raw (bytes): The file's bytes.
        path (str): The file, for the message.
        what (str): What it is, e.g. ``'CAM_FRONT image of sample t'``.

    Raises:
        ValueError: If it is empty or truncated.
    """
    if not raw:
        raise ValueError(f'{what} is empty (0 bytes): {path}')
    if raw[:2] == b'\xff\xd8' and \
            raw.rfind(b'\xff\xd9') < raw.rfind(b'\xff\xda'):
        raise ValueError(
            f'{what} is a truncated JPEG ({len(raw)} bytes, no end-of-image '
            f'marker after its last scan): {path}')
    if raw[:8] == b'\x89PNG\r\n\x1a\n' and b'IEND' not in raw[-12:]:
        raise ValueError(f'{what} is a truncated PNG ({len(raw)} bytes, no '
                         f'IEND chunk at its end): {path}')


def decode_flag(color_type: str) -> str:
    """The ``mmcv.imfrombytes`` flag of ``color_type``, EXIF orientation
    ignored.

    OpenCV's ``IMREAD_COLOR`` / ``IMREAD_GRAYSCALE`` rotate or mirror a
    JPEG whose EXIF orientation tag says so, so the decoded pixels were
    no longer those the camera's ``cam2img`` describes (a calibration is
    of the sensor's pixel grid, which is how the file stores them;
    nuScenes' images carry no tag). The pixels are decoded as stored,
    which is also what mmdet3d's ``color_type='unchanged'`` does.

    Args:
        color_type (str): ``'color'``, ``'grayscale'``, ``'unchanged'`` or
            a ``*_ignore_orientation`` flag of mmcv.

    Returns:
        str: The flag to decode with.
    """
    if color_type in ('color', 'grayscale'):
        return f'{color_type}_ignore_orientation'
    return color_type


def _calibrated_size(info: dict, img_shape, cam2img: np.ndarray, where: str,
                     path: str, rescale: bool) -> np.ndarray:
    """``cam2img`` for an image of ``img_shape``, checked or rescaled.

    The info's ``height`` / ``width`` (the size the calibration belongs
    to) must equal the image's, unless ``rescale``: then ``cam2img`` is
    scaled by the size ratio (pixel ``i`` covers ``[i, i + 1)``, so a
    resize is a pure scale). Info files without the size are checked by
    the principal point, which lies near the image centre for every
    nuScenes camera: outside the middle half of the image it belongs to
    another image size.
    """
    height, width = img_shape[:2]
    size = (info.get('height'), info.get('width'))
    if None in size:
        cx, cy = cam2img[0, 2], cam2img[1, 2]
        if not (0.25 * width <= cx <= 0.75 * width
                and 0.25 * height <= cy <= 0.75 * height):
            raise ValueError(
                f'{where}: the principal point ({cx:.1f}, {cy:.1f}) of '
                f'cam2img is not in the middle of the {width}x{height} '
                f'image {path}; the calibration is for an image of another '
                'size. Rescale cam2img with the image and record its '
                'height / width in the info file.')
        return cam2img
    if tuple(size) == (height, width):
        return cam2img
    if not rescale:
        raise ValueError(
            f'{where}: image {path} is {width}x{height}, but its calibration'
            f' (cam2img) is for {size[1]}x{size[0]}: every projection would '
            'be off by the ratio. Resize the image back, or set '
            'scale_calibration=True in LoadMultiViewImagesOcc to scale '
            'cam2img with the image.')
    scale = np.diag([width / size[1], height / size[0], 1.0, 1.0])
    return scale @ cam2img


@TRANSFORMS.register_module()
class LoadMultiViewImagesOcc(BaseTransform):
    """Load the camera images of a sample and stack their calibration.

    Unlike mmdet3d's ``LoadMultiViewImageFromFiles`` it also stacks the
    per-camera matrices into (N, 4, 4) arrays and starts the image
    augmentation bookkeeping (``img_aug_matrix`` = identity), see
    :mod:`.frames`. All views must have one size, the size their
    calibration belongs to (see ``scale_calibration``); empty, truncated
    or undecodable images and non-finite matrices are refused, naming the
    file.

    Args:
        cam_names (Sequence[str], optional): Views to load, in order.
            Defaults to the order of ``results['images']``.
        to_float32 (bool): Convert images to float32. Defaults to False.
        color_type (str): ``mmcv.imfrombytes`` flag. Defaults to 'color'
            (BGR uint8; the data preprocessor converts to RGB). An EXIF
            orientation tag is ignored (:func:`decode_flag`).
        backend_args (dict, optional): mmengine file backend arguments.
        scale_calibration (bool): For an image whose size differs from the
            ``height`` / ``width`` its info records (images resized after
            the conversion), scale ``cam2img`` by the ratio instead of
            raising. Defaults to False.

    Required Keys:

    - images (dict[str, dict]): Per camera ``img_path``, ``cam2img``
      (3, 3), ``lidar2cam`` (4, 4), ``cam2ego`` (4, 4), and optionally
      ``height`` / ``width`` (the calibrated image size).

    Added Keys:

    - img (list[np.ndarray]): N images, each shape (H, W, 3).
    - img_path (list[str]), cam_names (list[str]), num_views (int)
    - ori_shape, img_shape, pad_shape (tuple[int, int]): (H, W).
    - cam2img, lidar2cam, cam2ego, img_aug_matrix, lidar2img
      (np.ndarray): Shape (N, 4, 4), float64.
    """

    def __init__(self,
                 cam_names: Optional[Sequence[str]] = None,
                 to_float32: bool = False,
                 color_type: str = 'color',
                 backend_args: Optional[dict] = None,
                 scale_calibration: bool = False) -> None:
        self.cam_names = None if cam_names is None else list(cam_names)
        self.to_float32 = to_float32
        self.color_type = color_type
        self.backend_args = backend_args
        self.scale_calibration = scale_calibration

    def transform(self, results: dict) -> dict:
        """Load the views.

        Args:
            results (dict): Pipeline state.

        Returns:
            dict: The state with the added keys.
        """
        token = results.get('token', '?')
        cams = self.cam_names or list(results['images'])
        imgs, paths, mats = [], [], dict(cam2img=[], lidar2cam=[], cam2ego=[])
        for cam in cams:
            if cam not in results['images']:
                raise ValueError(f'sample {token} has no {cam} image; it '
                                 f'has {sorted(results["images"])}')
            info = results['images'][cam]
            path = info['img_path']
            what = f'{cam} image of sample {token}'
            raw = read_bytes(path, what, self.backend_args, 'image')
            check_complete_image(raw, path, what)
            try:
                img = mmcv.imfrombytes(
                    raw, flag=decode_flag(self.color_type))
            except Exception as err:  # noqa: BLE001 - cv2.error and kin
                raise ValueError(f'{what} cannot be decoded ({err}): '
                                 f'{path}') from None
            if img is None:
                raise ValueError(f'{what} cannot be decoded: {path}')
            if imgs and img.shape != imgs[0].shape:
                raise ValueError(
                    f'{cam} image {path} has shape {img.shape}, expected '
                    f'{imgs[0].shape} like {paths[0]}')
            imgs.append(img.astype(np.float32) if self.to_float32 else img)
            paths.append(path)
            for key in mats:
                mats[key].append(
                    _pad44(info[key], f'sample {token} {cam} {key}'))
            mats['cam2img'][-1] = _calibrated_size(
                info, img.shape, mats['cam2img'][-1],
                f'sample {token} {cam}', path, self.scale_calibration)
        results['img'] = imgs
        results['img_path'] = paths
        results['cam_names'] = cams
        results['num_views'] = len(cams)
        shape = imgs[0].shape[:2] if imgs else (0, 0)
        results['ori_shape'] = results['img_shape'] = shape
        results['pad_shape'] = shape
        for key, value in mats.items():
            results[key] = np.stack(value) if value else np.zeros((0, 4, 4))
        results['img_aug_matrix'] = np.tile(np.eye(4), (len(cams), 1, 1))
        refresh_lidar2img(results)
        return results

    def __repr__(self) -> str:
        """str: The transform and its arguments."""
        return (f'{self.__class__.__name__}(cam_names={self.cam_names}, '
                f'to_float32={self.to_float32}, '
                f'color_type={self.color_type!r}, '
                f'scale_calibration={self.scale_calibration})')
