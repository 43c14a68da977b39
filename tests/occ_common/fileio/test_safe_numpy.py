"""numpy objects in info files and checkpoints: forged ones are refused.

A pickle of only allowed globals (numpy's ``dtype`` and ``_reconstruct``)
can give ``dtype.__setstate__`` a state with altered flags
(:data:`~projects.occ_common.analysis.hostile_files.FORGERIES`): an object
dtype whose object flag is cleared makes ``ndarray.__setstate__`` copy raw
bytes of the file into an array of object pointers (printing it
dereferences 0x4141414141414141: a segfault), and a float dtype with the
flag set makes numpy treat its raw bytes as objects. Each forged file is
loaded in a forked child process, which prints the array if the load
succeeds, so that a crash fails the test instead of the test run.
"""
import multiprocessing
import pickle

import numpy as np
import pytest
import torch

from projects.occ_common.analysis.hostile_files import (FORGERIES,
                                                        write_forged_array)
from projects.occ_common.fileio import (RefusedGlobalError,
                                        load_checkpoint_file, load_info_file)


def _load_and_print(kind, path, conn):
    """In the child: load, print what was loaded, report the outcome."""
    try:
        if kind == 'info file':
            loaded = load_info_file(path)
        else:
            loaded = load_checkpoint_file(path)['meta']
        conn.send(f'loaded {loaded!r}')
        del loaded
    except Exception as err:  # noqa: BLE001 - reported to the parent
        conn.send(f'{type(err).__name__}: {err}')


@pytest.mark.parametrize('kind', ['info file', 'checkpoint'])
@pytest.mark.parametrize('forgery', list(FORGERIES))
def test_forged_numpy_array_is_refused_naming_the_file(
        kind, forgery, tmp_path):
    """A clean refusal naming the file and the dtype; no crash."""
    path = str(tmp_path / ('infos.pkl' if kind == 'info file' else 'x.pth'))
    write_forged_array(path, kind, forgery)
    context = multiprocessing.get_context('fork')
    parent, child = context.Pipe()
    process = context.Process(
        target=_load_and_print, args=(kind, path, child))
    process.start()
    process.join(120)
    assert process.exitcode == 0, f'the child died ({process.exitcode})'
    message = parent.recv()
    assert message.startswith(
        'RefusedGlobalError' if kind == 'info file' else
        'UnsafeCheckpointError'), message
    assert f'Refusing to load {kind} {path}: it pickles' in message
    assert 'Nothing from it was executed' in message


@pytest.mark.parametrize('protocol', [2, 4, 5])
def test_plain_numpy_objects_load_as_pickle_loads_them(protocol, tmp_path):
    """Arrays and scalars of every allowed kind, big-endian, Fortran
    order, 0-d, empty and shared ones, dtypes: the same as pickle gives
    (which turns big-endian arrays native unless protocol 5 wrote them)
    and torch.load give."""
    shared = np.arange(3.)
    content = dict(
        f=np.eye(3, dtype=np.float32), i=np.arange(4), u=np.uint8([1, 2]),
        b=np.array([True, False]), c=np.array([1 + 2j]),
        U=np.array(['ab', 'c']), S=np.array([b'xy']),
        big=np.arange(3, dtype='>i4'), zero_d=np.array(2.5),
        empty=np.zeros((0, 3)), fortran=np.asfortranarray(np.eye(2)),
        scalars=[np.float64(1.5), np.int32(3), np.bool_(True),
                 np.str_('hey')],
        dtypes=[np.dtype('f4'), np.dtype('>i2')], shared=[shared, shared])
    path = str(tmp_path / 'infos.pkl')
    with open(path, 'wb') as f:
        pickle.dump(content, f, protocol=protocol)
    checkpoint = str(tmp_path / 'x.pth')
    torch.save(content, checkpoint)
    with open(path, 'rb') as f:
        plain = [pickle.load(f), torch.load(checkpoint, weights_only=False)]
    ours = [load_info_file(path), load_checkpoint_file(checkpoint)]
    for loaded, expected in zip(ours, plain):
        assert repr(loaded) == repr(expected)
        for key in ('big', 'fortran'):
            assert loaded[key].dtype.str == expected[key].dtype.str
            assert loaded[key].flags.f_contiguous == \
                expected[key].flags.f_contiguous
        assert loaded['shared'][0] is loaded['shared'][1]
        assert loaded['f'].flags.writeable


@pytest.mark.parametrize('array', [
    np.array([1, 'a'], dtype=object),
    np.zeros(2, dtype='f4,i4'),
    np.array(['2020-01-01'], dtype='M8[D]')
], ids=['object', 'structured', 'datetime'])
def test_object_structured_and_datetime_arrays_are_refused(array, tmp_path):
    """Not plain dtypes: refused by name (object arrays can hold any
    allowed object, the others are not what info files hold)."""
    path = str(tmp_path / 'infos.pkl')
    with open(path, 'wb') as f:
        pickle.dump(dict(x=array), f)
    with pytest.raises(RefusedGlobalError,
                       match=f'info file {path}: it pickles numpy.dtype'):
        load_info_file(path)
