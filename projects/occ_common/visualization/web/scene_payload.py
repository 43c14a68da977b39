"""One sample as the compact binary message the browser viewer draws.

A message is ``b'OCCV'``, the header's length (uint32, little endian), the
header (UTF-8 JSON, padded with spaces to 4 bytes) and the sections it
lists, each at a 4-byte aligned offset so that the browser views them as
typed arrays without copying:

===================  ======  ============================================
section              dtype   content
===================  ======  ============================================
``gt``, ``pred``     uint8   dense labels, Shape (X, Y, Z), C order
``errors``           uint8   255 not drawn, else an index of
                             :data:`~..palette.ERROR_NAMES` (0 a correct
                             occupied voxel, 1-3 the codes of
                             :func:`~..error_map.occupancy_errors`)
``visibility``       uint8   bit 0 ``mask_camera``, bit 1 ``mask_lidar``
``prob``             uint8   the predicted class's probability x 255 of
                             every voxel the prediction occupies, C order
``points_xyz``       int16   centimetres, Shape (P, 3)
``points_intensity`` uint8   Shape (P,)
``points_label``     uint8   the point's class (255 none), Shape (P,)
===================  ======  ============================================

Dense grids are the simplest layout for the browser (a voxel's class is one
index away, for hover and for the error view) and cost little on the wire:
the server sends them gzip-compressed and a mostly empty 200 x 200 x 16
grid (640 kB) shrinks to tens of kB. Camera images travel as JPEG beside
the message (:func:`encode_jpeg`).
"""
import io
import json
import struct
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from PIL import Image

from ..error_map import CORRECT, occupancy_errors
from ..label_grid import as_label_grid, as_mask, occupied_voxels
from ..palette import ERROR_NAMES, ERROR_PALETTE, resolve_palette
from .camera_frusta import frustum_corners

MAGIC = b'OCCV'
#: Bumped when a section changes meaning; the browser refuses other
#: versions.
FORMAT_VERSION = 1
#: ``errors`` value of a voxel drawn in no error colour.
NOT_DRAWN = 255
#: int16 centimetres reach +-327.67 m; farther points are clipped there.
POINT_SCALE = 100.0


def _section(sections: List[Tuple[str, np.ndarray]], name: str,
             array: np.ndarray, dtype) -> None:
    sections.append((name, np.ascontiguousarray(array, dtype=dtype)))


def error_grid(pred: np.ndarray, gt: np.ndarray, num_classes: int,
               empty_label: int, ignore_index: int = 255) -> np.ndarray:
    """The ``errors`` section: every counted voxel either grid occupies.

    Args:
        pred (np.ndarray): Predicted labels. Shape (X, Y, Z).
        gt (np.ndarray): GT labels. Shape (X, Y, Z).
        num_classes (int): Number of classes.
        empty_label (int): Label of empty space.
        ignore_index (int): GT label never counted. Defaults to 255.

    Returns:
        np.ndarray: :data:`NOT_DRAWN` where neither grid has a counted
        occupied voxel, 0 where both hold the same class, else the code of
        :func:`~..error_map.occupancy_errors` (1 false positive, 2 false
        negative, 3 wrong class). Shape (X, Y, Z), uint8. Visibility masks
        are applied by the viewer: the codes inside a mask are those
        ``occupancy_errors`` gives with that mask.
    """
    codes = occupancy_errors(pred, gt, num_classes, empty_label,
                             ignore_index)
    gt_occupied = occupied_voxels(gt, num_classes, empty_label,
                                  ignore_index)
    grid = np.full(gt.shape, NOT_DRAWN, dtype=np.uint8)
    drawn = codes != CORRECT
    grid[drawn] = codes[drawn]
    grid[(codes == CORRECT) & gt_occupied] = CORRECT
    return grid


def encode_jpeg(image: np.ndarray, quality: int = 85) -> bytes:
    """An RGB image as JPEG bytes.

    Args:
        image (np.ndarray): Shape (H, W, 3), uint8.
        quality (int): JPEG quality. Defaults to 85.

    Returns:
        bytes: The JPEG file.
    """
    buffer = io.BytesIO()
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(
        buffer, format='JPEG', quality=quality)
    return buffer.getvalue()


def _points_sections(sections, points: np.ndarray,
                     labels: Optional[np.ndarray], name: str) -> int:
    points = np.asarray(points, dtype=np.float32)
    if points.ndim != 2 or points.shape[1] < 3:
        raise ValueError(f'{name}: expected points of shape (P, >=3), got '
                         f'{points.shape}.')
    finite = np.isfinite(points[:, :3]).all(1)
    if not finite.all():
        raise ValueError(f'{name}: {int((~finite).sum())} points hold NaN '
                         'or inf coordinates.')
    limit = np.iinfo(np.int16).max
    xyz = np.clip(np.rint(points[:, :3] * POINT_SCALE), -limit, limit)
    _section(sections, 'points_xyz', xyz, np.int16)
    if points.shape[1] > 3:
        _section(sections, 'points_intensity',
                 np.clip(np.rint(points[:, 3]), 0, 255), np.uint8)
    if labels is not None:
        labels = np.asarray(labels)
        if labels.shape != (len(points), ):
            raise ValueError(f'{name}: {labels.shape} point labels for '
                             f'{len(points)} points.')
        labels = np.where((labels >= 0) & (labels < 255), labels, 255)
        _section(sections, 'points_label', labels, np.uint8)
    return len(points)


def encode_sample(scene: Dict,
                  num_classes: int,
                  empty_label: int,
                  ignore_index: int = 255,
                  frustum_depth: float = 4.0) -> Tuple[bytes, List[bytes]]:
    """The message of one sample and the JPEG of each camera.

    Args:
        scene (dict): What to draw, all optional but ``name``,
            ``pc_range`` and ``voxel_size`` (a grid-less sample still
            places its points and cameras):

            - ``name`` (str), ``token``, ``scene_name``, ``sample_idx``,
              ``is_rainy``, ``is_night``, ``forward`` (``'+x'`` ...);
            - ``pc_range`` (6 floats), ``voxel_size`` (3 floats);
            - ``gt_occ``, ``pred_occ``: Shape (X, Y, Z), int;
            - ``pred_prob``: the predicted class's probability, Shape
              (X, Y, Z), float in [0, 1];
            - ``mask_camera``, ``mask_lidar``: Shape (X, Y, Z), bool;
            - ``points``: Shape (P, >=3): x, y, z [, intensity];
              ``point_labels``: Shape (P,), the class of each point;
            - ``images``: RGB, Shape (N, H, W, 3), uint8, with
              ``lidar2img`` (grid frame to pixels), Shape (N, 4, 4), and
              ``cam_names``.
        num_classes (int): Number of classes.
        empty_label (int): Label of empty space.
        ignore_index (int): GT label never drawn nor counted. Defaults to
            255.
        frustum_depth (float): Metres from a camera to its image plane in
            the 3D view. Defaults to 4.0.

    Returns:
        tuple[bytes, list[bytes]]: The message and one JPEG per camera.

    Raises:
        ValueError: If a grid, mask or point array has the wrong shape or
            labels out of range (naming the sample and the key).
    """
    name = str(scene['name'])
    sections: List[Tuple[str, np.ndarray]] = []
    grids = {}
    for key in ('gt_occ', 'pred_occ'):
        if scene.get(key) is not None:
            grids[key] = as_label_grid(scene[key], f'{name} {key}')
            # Refuses labels outside the classes, naming the grid.
            occupied_voxels(grids[key], num_classes, empty_label,
                            ignore_index, None, f'{name} {key}')
    shapes = {grid.shape for grid in grids.values()}
    if len(shapes) > 1:
        raise ValueError(f'{name}: gt_occ and pred_occ differ in shape: '
                         f'{sorted(shapes)}.')
    shape = shapes.pop() if shapes else None
    counts: Dict = {}
    for key, section in (('gt_occ', 'gt'), ('pred_occ', 'pred')):
        if key in grids:
            _section(sections, section, grids[key], np.uint8)
            counts[section] = int(occupied_voxels(
                grids[key], num_classes, empty_label, ignore_index).sum())
    if len(grids) == 2:
        errors = error_grid(grids['pred_occ'], grids['gt_occ'], num_classes,
                            empty_label, ignore_index)
        _section(sections, 'errors', errors, np.uint8)
        counts['errors'] = np.bincount(
            errors[errors != NOT_DRAWN], minlength=4).tolist()
    masks = {
        key: as_mask(scene.get(key), shape, f'{name} {key}')
        for key in ('mask_camera', 'mask_lidar') if shape is not None
    }
    if any(mask is not None for mask in masks.values()):
        visibility = np.zeros(shape, dtype=np.uint8)
        for bit, key in enumerate(('mask_camera', 'mask_lidar')):
            if masks.get(key) is not None:
                visibility |= masks[key].astype(np.uint8) << bit
        _section(sections, 'visibility', visibility, np.uint8)
    if scene.get('pred_prob') is not None and 'pred_occ' in grids:
        prob = np.asarray(scene['pred_prob'], dtype=np.float32)
        if prob.shape != shape:
            raise ValueError(f'{name}: pred_prob {prob.shape} and pred_occ '
                             f'{shape} differ in shape.')
        occupied = grids['pred_occ'] != empty_label
        _section(sections, 'prob',
                 np.rint(np.clip(prob[occupied], 0, 1) * 255), np.uint8)
    if scene.get('points') is not None:
        counts['points'] = _points_sections(sections, scene['points'],
                                            scene.get('point_labels'),
                                            f'{name} points')
    cameras, jpegs = _cameras(scene, frustum_depth, name)
    header = dict(
        version=FORMAT_VERSION,
        name=name,
        token=scene.get('token'),
        scene_name=scene.get('scene_name'),
        sample_idx=scene.get('sample_idx'),
        is_rainy=bool(scene.get('is_rainy', False)),
        is_night=bool(scene.get('is_night', False)),
        forward=scene.get('forward', '+x'),
        grid=dict(
            shape=None if shape is None else list(shape),
            pc_range=[float(v) for v in scene['pc_range']],
            voxel_size=[float(v) for v in scene['voxel_size']]),
        counts=counts,
        cameras=cameras)
    return pack_message(header, sections), jpegs


def _cameras(scene: Dict, depth: float, name: str):
    """Frusta (JSON) and JPEGs of the sample's cameras."""
    images = scene.get('images')
    if images is None:
        return [], []
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f'{name} images: expected RGB views of shape '
                         f'(N, H, W, 3), got {images.shape}.')
    lidar2img = np.asarray(scene['lidar2img'], dtype=np.float64)
    if lidar2img.shape != (len(images), 4, 4):
        raise ValueError(f'{name} lidar2img: expected shape '
                         f'({len(images)}, 4, 4), got {lidar2img.shape}.')
    cam_names: Sequence[str] = scene.get('cam_names') or [
        f'camera {k}' for k in range(len(images))
    ]
    height, width = images.shape[1:3]
    corners = frustum_corners(lidar2img, (height, width), depth)
    cameras = [
        dict(name=str(cam), width=int(width), height=int(height),
             frustum=np.round(corners[k], 4).tolist())
        for k, cam in enumerate(cam_names)
    ]
    return cameras, [encode_jpeg(image) for image in images]


def pack_message(header: Dict,
                 sections: Sequence[Tuple[str, np.ndarray]]) -> bytes:
    """``MAGIC``, header length, header and 4-byte aligned sections.

    Args:
        header (dict): JSON-able; ``sections`` is added: name ->
            ``[offset, length in elements, dtype]``, offsets from the
            message's start.
        sections (Sequence[tuple[str, np.ndarray]]): Name and array.

    Returns:
        bytes: The message.
    """
    def align(n: int) -> int:
        return (n + 3) // 4 * 4

    table = {}
    # The offsets depend on the header's length, which depends on the
    # offsets' digits: reserve the width of the largest offset first.
    total = sum(align(array.nbytes) for _, array in sections)
    probe = dict(header, sections={
        name: [10**12 + total, array.size, array.dtype.name]
        for name, array in sections
    })
    start = align(8 + len(json.dumps(probe).encode()))
    offset = start
    for name, array in sections:
        table[name] = [offset, int(array.size), array.dtype.name]
        offset += align(array.nbytes)
    text = json.dumps(dict(header, sections=table)).encode()
    text += b' ' * (start - 8 - len(text))
    out = bytearray(MAGIC + struct.pack('<I', len(text)) + text)
    for _, array in sections:
        out += array.tobytes()
        out += b'\0' * (align(array.nbytes) - array.nbytes)
    return bytes(out)


def unpack_message(message: bytes) -> Tuple[Dict, Dict[str, np.ndarray]]:
    """The header and sections of a message (the browser's reading, for
    tests and tools).

    Returns:
        tuple[dict, dict[str, np.ndarray]]: Header and flat arrays.

    Raises:
        ValueError: If the message does not start with :data:`MAGIC` or
            has another :data:`FORMAT_VERSION`.
    """
    if message[:4] != MAGIC:
        raise ValueError(f'not a viewer message: starts {message[:4]!r}')
    (length, ) = struct.unpack('<I', message[4:8])
    header = json.loads(message[8:8 + length].decode())
    if header.get('version') != FORMAT_VERSION:
        raise ValueError(f'viewer message version {header.get("version")},'
                         f' expected {FORMAT_VERSION}')
    arrays = {
        name: np.frombuffer(message, dtype=dtype, count=count, offset=offset)
        for name, (offset, count, dtype) in header['sections'].items()
    }
    return header, arrays


def viewer_meta(class_names: Sequence[str],
                empty_label: int,
                num_samples: int,
                ignore_index: int = 255,
                palette: Optional[np.ndarray] = None,
                title: str = 'occupancy',
                initial_index: int = 0) -> Dict:
    """What the viewer knows of the whole dataset (``api/meta.json``).

    Args:
        class_names (Sequence[str]): Names in label order.
        empty_label (int): Label of empty space.
        num_samples (int): Number of samples the viewer can show.
        ignore_index (int): GT label never drawn. Defaults to 255.
        palette (np.ndarray, optional): Shape (C, 3). Defaults to the
            library's class palette (:func:`~..palette.resolve_palette`),
            the colours of every other picture of this library.
        title (str): Shown above the panel. Defaults to 'occupancy'.
        initial_index (int): Sample shown first. Defaults to 0.

    Returns:
        dict: JSON-able.
    """
    colours = resolve_palette(class_names, palette)
    return dict(
        title=title,
        num_samples=int(num_samples),
        initial_index=int(initial_index),
        class_names=list(class_names),
        palette=colours.tolist(),
        empty_label=int(empty_label),
        ignore_index=int(ignore_index),
        error_names=list(ERROR_NAMES),
        error_palette=ERROR_PALETTE.tolist())
