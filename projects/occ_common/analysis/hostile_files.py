"""Hostile checkpoints and info files, for the tests of the loaders.

Each writes a file as an attacker would and, where it runs code, the code
only writes ``pwned\\n`` to a chosen marker file, so that a test (or
``tools/analysis_tools/fault_matrix.py``) sees whether it ran:

* :func:`write_torchscript_archive`: a TorchScript archive whose
  ``__setstate__`` writes the marker (``torch.from_file(...,
  shared=True)`` creates the file, the copy writes its bytes);
  ``torch.load(weights_only=False)`` hands it to ``torch.jit.load``;
* :func:`write_forged_array`: a numpy array of raw bytes ``0x41`` whose
  dtype's pickled flags are altered (:data:`FORGERIES`), using only
  globals an info file or checkpoint may name;
* :func:`write_os_system`: a pickle calling ``os.system('touch MARKER')``;
* :func:`write_config_payload`: a genuine checkpoint whose ``meta['config']``
  (the config text of mmcv-era runners, which mmengine's ``Runner.resume``
  runs as Python) writes the marker;

and, damaged or odd rather than hostile:

* :func:`flip_bit`: one bit of a zip record flipped (its CRC-32 no longer
  matches);
* :func:`write_npz_bomb`: an ``.npz`` whose member declares a huge array
  of zeros (megabytes compressed, hundreds of them decompressed);
* :func:`write_exif_jpeg`: a JPEG with an EXIF orientation tag.
"""
import importlib
import io
import os
import pickle
import struct
import zipfile
from typing import List, Sequence, Tuple

import numpy as np
import torch

from ..fileio.safe_numpy import numpy_core

#: dtype args and forged state (version, byte order, subarray, names,
#: fields, itemsize, alignment, flags) by name: the object flags cleared
#: on an object dtype (numpy's: 63; reading the array dereferences the raw
#: bytes as object pointers: a segfault), or set on a float64 one
#: (numpy's: 0; numpy treats the raw bytes as objects).
FORGERIES = {
    'object dtype without its object flags':
    (('O8', False, True), (3, '|', None, None, None, -1, -1, 0)),
    'float64 dtype with the object flag':
    (('f8', False, True), (3, '<', None, None, None, -1, -1, 1)),
}


class MarkerPayload(torch.nn.Module):
    """Writes ``pwned\\n`` to ``marker`` when its archive is loaded.

    Args:
        marker (str): The file to write.
    """

    def __init__(self, marker: str):
        super().__init__()
        self.marker = marker
        self.written = 0

    def forward(self, x):
        """Identity (TorchScript needs a forward)."""
        return x

    @torch.jit.export
    def __getstate__(self) -> List[str]:
        return [self.marker]

    @torch.jit.export
    def __setstate__(self, state: List[str]) -> None:
        self.marker = state[0]
        self.training = False
        data = torch.from_file(self.marker, True, 6, dtype=torch.uint8)
        data.copy_(
            torch.tensor([112, 119, 110, 101, 100, 10], dtype=torch.uint8))
        # Used, so that TorchScript keeps the write.
        self.written = int(data.sum())


def write_torchscript_archive(path: str, marker: str) -> str:
    """Save a scripted :class:`MarkerPayload` to ``path``; returns it."""
    torch.jit.save(torch.jit.script(MarkerPayload(marker)), path)
    return path


class _Reduced:
    """Pickles as ``func(*args)``, then ``state`` for BUILD if given."""

    def __init__(self, func, args, state=None):
        self.reduced = (func, args, state) if state else (func, args)

    def __reduce__(self):
        return self.reduced


def forged_array(forgery: str) -> _Reduced:
    """An object pickling as one element of raw bytes ``0x41`` x 8 with
    the dtype of ``FORGERIES[forgery]``."""
    reconstruct = importlib.import_module(
        f'{numpy_core()}.multiarray')._reconstruct
    args, state = FORGERIES[forgery]
    return _Reduced(reconstruct, (np.ndarray, (0, ), b'b'),
                    (1, (1, ), _Reduced(np.dtype, args, state), False,
                     b'\x41' * 8))


def _write(content, path: str, kind: str) -> str:
    if kind == 'info file':
        with open(path, 'wb') as f:
            pickle.dump(dict(metainfo={}, data_list=[content]), f,
                        protocol=2)
    else:
        torch.save(dict(state_dict={}, meta=content), path)
    return path


def write_forged_array(path: str, kind: str, forgery: str) -> str:
    """An info file (``kind='info file'``) or a checkpoint holding
    :func:`forged_array` as ``data_list[0]['m']`` / ``meta['m']``."""
    return _write(dict(m=forged_array(forgery)), path, kind)


def write_os_system(path: str, kind: str, marker: str) -> str:
    """An info file or checkpoint calling ``os.system('touch marker')``."""
    return _write(_Reduced(os.system, (f'touch {marker}', )), path, kind)


def write_config_payload(source: str, path: str, marker: str) -> str:
    """``source`` (a genuine Runner checkpoint) with ``meta['config']`` a
    one-line payload writing ``marker``; saved to ``path``, returned."""
    from ..fileio.safe_pickle import load_checkpoint_file
    checkpoint = load_checkpoint_file(source, map_location='cpu')
    checkpoint['meta']['config'] = f"_ = open({marker!r}, 'w').write('pwned')"
    torch.save(checkpoint, path)
    return path


def record_offset(path: str, suffix: str) -> Tuple[str, int]:
    """The name of the zip record of ``path`` ending in ``suffix`` and the
    offset of its first byte of data."""
    with zipfile.ZipFile(path) as archive:
        info = next(i for i in archive.infolist()
                    if i.filename.endswith(suffix))
    with open(path, 'rb') as f:
        f.seek(info.header_offset + 26)
        name_len, extra_len = struct.unpack('<HH', f.read(4))
    return info.filename, info.header_offset + 30 + name_len + extra_len


def flip_bit(path: str, suffix: str = 'data/0', bit: int = 2) -> str:
    """Flip ``bit`` of the first data byte of the record ending in
    ``suffix`` (a checkpoint's first tensor), in place; returns the
    record's name."""
    record, offset = record_offset(path, suffix)
    with open(path, 'r+b') as f:
        f.seek(offset)
        byte = f.read(1)[0]
        f.seek(offset)
        f.write(bytes([byte ^ (1 << bit)]))
    return record


def write_npz_bomb(path: str, bomb: str, shape: Sequence[int],
                   others: Sequence[Tuple[str, np.ndarray]] = ()) -> str:
    """An ``.npz`` whose member ``bomb`` declares uint8 zeros of ``shape``
    (written compressed, 8 MB at a time), beside ``others``."""
    size = int(np.prod(shape))
    with zipfile.ZipFile(path, 'w', zipfile.ZIP_DEFLATED) as archive:
        with archive.open(f'{bomb}.npy', 'w', force_zip64=True) as f:
            np.lib.format.write_array_header_1_0(
                f, dict(descr='|u1', fortran_order=False,
                        shape=tuple(shape)))
            chunk = bytes(8 << 20)
            for _ in range(size // len(chunk)):
                f.write(chunk)
            f.write(bytes(size % len(chunk)))
        for name, array in others:
            with archive.open(f'{name}.npy', 'w') as f:
                np.lib.format.write_array(f, array)
    return path


def write_exif_jpeg(path: str, pixels: np.ndarray,
                    orientation: int = 6) -> str:
    """``pixels`` (RGB, Shape (H, W, 3)) as a JPEG whose EXIF orientation
    tag asks viewers to rotate it (6: 90 degrees clockwise)."""
    from PIL import Image
    exif = Image.Exif()
    exif[0x0112] = orientation
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format='JPEG', exif=exif,
                                 quality=95)
    with open(path, 'wb') as f:
        f.write(buffer.getvalue())
    return path


__all__ = [
    'FORGERIES', 'MarkerPayload', 'flip_bit', 'forged_array',
    'record_offset', 'write_config_payload', 'write_exif_jpeg',
    'write_forged_array', 'write_npz_bomb', 'write_os_system',
    'write_torchscript_archive'
]
