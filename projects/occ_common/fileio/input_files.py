"""Reading a dataset's input files without hanging or exhausting memory.

An info file names every image, LiDAR and label file by a path, and a
path can name something that is no file: a FIFO blocked
``tools/test.py`` forever in ``open``, a LiDAR path at a device file
(``/dev/zero``) read until memory ran out, and a 4 MB ``labels.npz``
decompressed to 4.6 GB before its shape was checked (numpy allocates an
array of the shape its header declares before reading any data).

* :func:`read_input_bytes` stats a local path first and reads only a
  regular file no larger than its kind's limit
  (:data:`MAX_INPUT_BYTES`), naming the file otherwise.
* :func:`load_npy` and :func:`load_npz_arrays` read an ``.npy`` header
  and check the shape, dtype and byte count it declares (and, in an
  ``.npz``, each member's declared uncompressed size) before numpy
  allocates or decompresses anything. Object arrays are refused.

Paths of a remote file backend (``backend_args``) are read by mmengine
and then checked against the same limit.
"""
import io
import os
import os.path as osp
import stat
import zipfile
from typing import Callable, Dict, Optional, Sequence, Tuple

import numpy as np

#: Largest file each kind of input may be, in bytes, with the reason.
MAX_INPUT_BYTES = dict(
    # An uncompressed 8K RGB frame (7680 x 4320 x 3 = 99.5 MB) fits;
    # nuScenes' JPEGs are 0.1 - 0.4 MB.
    image=128 << 20,
    # 26 M points of 5 float32 values, ten frames of a 128-beam LiDAR;
    # a nuScenes key frame is ~0.7 MB.
    points=512 << 20,
    # SurroundOcc's (M, 4) int64 rows of a full 200 x 200 x 16 grid are
    # 20.5 MB; an Occ3D labels.npz is ~0.1 - 1 MB, lidarseg 35 kB.
    label=64 << 20,
)

#: Bytes an ``.npy`` header may take (numpy writes 128 or a multiple).
_MAX_HEADER = 1 << 16


#: What a path is when it is no regular file, by ``stat`` test.
_KINDS = ((stat.S_ISFIFO, 'a FIFO'), (stat.S_ISCHR, 'a character device'),
          (stat.S_ISBLK, 'a block device'), (stat.S_ISSOCK, 'a socket'),
          (stat.S_ISDIR, 'a directory'))


def _kind_of(mode: int) -> str:
    for test, kind in _KINDS:
        if test(mode):
            return kind
    return 'not a regular file'


def check_input_file(path: str, what: str, max_bytes: int) -> int:
    """Refuse a local path that is not a regular file of at most
    ``max_bytes`` (symlinks are followed: their target must be one).

    Args:
        path (str): The file.
        what (str): What it is, for the messages.
        max_bytes (int): The largest size accepted.

    Returns:
        int: Its size in bytes.

    Raises:
        FileNotFoundError: If nothing is there.
        ValueError: If it is a FIFO, device, socket or directory (reading
            it could block or never end), or larger than ``max_bytes``.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f'{what} not found: {path}') from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(
            f'{what} {path} is {_kind_of(info.st_mode)}, not a regular file:'
            ' reading it could block or never end.')
    if info.st_size > max_bytes:
        raise ValueError(
            f'{what} {path} is {info.st_size:,} bytes, more than the '
            f'{max_bytes:,} such a file may have: it is not one.')
    return info.st_size


def _is_local(path: str, backend_args: Optional[dict]) -> bool:
    backend = (backend_args or {}).get('backend', 'local')
    return backend == 'local' and '://' not in str(path)


def read_input_bytes(path: str,
                     what: str,
                     max_bytes: int,
                     backend_args: Optional[dict] = None) -> bytes:
    """The bytes of an input file, checked before it is read.

    Args:
        path (str): The file.
        what (str): What it is, for the messages (``'CAM_FRONT image of
            sample t'``).
        max_bytes (int): Largest size accepted (:data:`MAX_INPUT_BYTES`).
        backend_args (dict, optional): mmengine file backend arguments; a
            remote file is read by mmengine, then checked.

    Returns:
        bytes: The content.

    Raises:
        FileNotFoundError: If it does not exist.
        ValueError: See :func:`check_input_file`.
    """
    if _is_local(path, backend_args):
        size = check_input_file(path, what, max_bytes)
        with open(path, 'rb') as f:
            # Python allocates what read(n) asks for: the stat size, plus
            # one byte to see a file that grew meanwhile.
            raw = f.read(size + 1)
    else:
        from mmengine.fileio import get
        try:
            raw = get(path, backend_args=backend_args)
        except FileNotFoundError:
            raise FileNotFoundError(f'{what} not found: {path}') from None
    if len(raw) > max_bytes:
        raise ValueError(f'{what} {path} is more than the {max_bytes:,} '
                         'bytes such a file may have: it is not one.')
    return raw


def _npy_header(fp, path: str, what: str) -> Tuple[tuple, np.dtype, bool]:
    """Shape, dtype and Fortran order an ``.npy`` stream declares."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fp)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(
                fp, max_header_size=_MAX_HEADER)
        else:
            shape, fortran, dtype = fmt.read_array_header_2_0(
                fp, max_header_size=_MAX_HEADER)
    except Exception as err:  # noqa: BLE001 - ValueError, EOFError ...
        raise ValueError(f'{what} {path} is truncated or not an .npy array '
                         f'({type(err).__name__}: {err})') from None
    if dtype.hasobject:
        raise ValueError(f'{what} {path} holds Python objects ({dtype}), '
                         'not numbers.')
    return tuple(int(n) for n in shape), dtype, fortran


def load_npy(raw: bytes, path: str, what: str,
             check: Callable[[tuple, np.dtype], Optional[str]]
             ) -> np.ndarray:
    """An ``.npy`` array whose declared shape and size are checked first.

    Args:
        raw (bytes): The file's bytes.
        path (str): The file, for the messages.
        what (str): What it is, for the messages.
        check (callable): ``check(shape, dtype)`` returns what is wrong
            with the declared shape / dtype, or None.

    Returns:
        np.ndarray: The array.

    Raises:
        ValueError: If the header is broken, ``check`` objects, or the
            data is not exactly the declared number of bytes.
    """
    fp = io.BytesIO(raw)
    shape, dtype, _ = _npy_header(fp, path, what)
    wrong = check(shape, dtype)
    if wrong:
        raise ValueError(f'{what} {path}: {wrong}, got {dtype} {shape}')
    expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if len(raw) - fp.tell() != expected:
        raise ValueError(
            f'{what} {path} is truncated or not a .npy array: its header '
            f'declares {dtype} {shape} ({expected:,} bytes) but '
            f'{len(raw) - fp.tell():,} bytes follow it.')
    return np.load(io.BytesIO(raw), allow_pickle=False)


def load_npz_arrays(raw: bytes, path: str, what: str, names: Sequence[str],
                    check: Callable[[str, tuple, np.dtype], Optional[str]]
                    ) -> Dict[str, np.ndarray]:
    """The named arrays of an ``.npz``, each checked before it is
    decompressed.

    Every named member's declared uncompressed size must be its header
    plus the bytes its declared shape and dtype take, and ``check`` must
    accept that shape and dtype; only then is it decompressed (zip stops
    at the declared size). Other members are not read.

    Args:
        raw (bytes): The file's bytes.
        path (str): The file, for the messages.
        what (str): What it is, for the messages.
        names (Sequence[str]): The arrays to read.
        check (callable): ``check(name, shape, dtype)`` returns what is
            wrong, or None.

    Returns:
        dict[str, np.ndarray]: Name -> array.

    Raises:
        ValueError: If it is no zip archive, lacks a name, a header is
            broken or refused, a member's sizes disagree with its header,
            or a CRC does not match.
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(raw))
    except (zipfile.BadZipFile, ValueError) as err:
        raise ValueError(f'{what} {path} is truncated, corrupt or not an '
                         f'.npz archive ({err})') from None
    arrays = {}
    with archive:
        members = {osp.splitext(n)[0]: n for n in archive.namelist()}
        for name in names:
            if name not in members:
                raise ValueError(f'{what} {path}: expected the arrays '
                                 f'{list(names)}, got {sorted(members)}')
            info = archive.getinfo(members[name])
            try:
                with archive.open(info) as member:
                    shape, dtype, _ = _npy_header(member, path,
                                                  f'{what} ({name})')
                    wrong = check(name, shape, dtype)
                    if wrong:
                        raise ValueError(f'{what} {path}: {wrong}, got '
                                         f'{dtype} {shape}')
                    data = int(np.prod(shape, dtype=np.int64)) * \
                        dtype.itemsize
                    if info.file_size - member.tell() != data:
                        raise ValueError(
                            f'{what} {path}: {name} declares {dtype} '
                            f'{shape} ({data:,} bytes) but its member holds '
                            f'{info.file_size - member.tell():,}: the file '
                            'is damaged.')
                    member.seek(0)  # read_array reads the header again
                    arrays[name] = np.lib.format.read_array(
                        member, allow_pickle=False)
            except (zipfile.BadZipFile, EOFError, OSError) as err:
                raise ValueError(
                    f'{what} {path} is truncated, corrupt or not an .npz '
                    f'archive ({name}: '
                    f'{type(err).__name__}: {err})') from None
    return arrays


__all__ = [
    'MAX_INPUT_BYTES', 'check_input_file', 'load_npy', 'load_npz_arrays',
    'read_input_bytes'
]
