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
* :func:`write_os_system`: a pickle calling ``os.system('touch MARKER')``.
"""
import importlib
import os
import pickle
from typing import List

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


__all__ = [
    'FORGERIES', 'MarkerPayload', 'forged_array', 'write_forged_array',
    'write_os_system', 'write_torchscript_archive'
]
