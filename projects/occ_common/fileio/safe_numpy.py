"""numpy arrays, scalars and dtypes rebuilt from a pickle, checked first.

numpy pickles a dtype as ``dtype('f8', False, True)`` and a state (byte
order, sizes and *flags*) that ``dtype.__setstate__`` copies into the
descriptor as given, and an array as ``_reconstruct(ndarray, (0,), b'b')``
and a state (shape, dtype, raw bytes) for ``ndarray.__setstate__``. Both
trust the state. With the globals an info file or a checkpoint needs, a
pickle can clear the object flag of an object dtype, so that
``ndarray.__setstate__`` copies raw bytes of the file into an array of
object pointers (reading it dereferences them: a segfault, or a call the
file steers), or set the flag on a float dtype, so that numpy releases raw
bytes as objects when the array is freed.

The restricted unpicklers of :mod:`.safe_pickle` therefore resolve numpy's
names to the constructors of :data:`CONSTRUCTORS` and pass every ``BUILD``
of a numpy object to :func:`build`, which never hands a state of the file
to numpy unchecked:

* a dtype comes only from a type string of a plain kind (:data:`KINDS`:
  booleans, integers, floats, complex numbers, bytes, str) and always as a
  new copy; its pickled state must equal the state numpy gives a freshly
  constructed dtype of that type, in one of the byte orders, and only then
  is that byte order set, from numpy's own state tuple. Object,
  structured, subarray and datetime dtypes are refused;
* an array is built once, from a shape of non-negative ints, such a dtype
  and exactly ``size * itemsize`` raw bytes; scalars (``scalar``) and
  arrays of pickle protocol 5 (``_frombuffer``, from ``bytes`` or
  ``bytearray`` only) likewise. ``numpy.ndarray`` is only a marker for
  ``_reconstruct``, never called.
"""
import functools
import importlib
import math
import pickle
from typing import Any, Dict, Tuple

import numpy as np


def numpy_core() -> str:
    """``numpy._core`` (numpy 2) or ``numpy.core`` (numpy 1)."""
    if np.lib.NumpyVersion(np.__version__) >= '2.0.0':
        return 'numpy._core'
    return 'numpy.core'


#: dtype kinds an array, scalar or dtype of a pickle may have.
KINDS = frozenset('biufcSU')

_BYTE_ORDERS = ('<', '>', '|')

_PLAIN = ('only booleans, numbers, bytes and str are allowed; object, '
          'structured and datetime dtypes are refused')


class UnsafeArrayError(pickle.UnpicklingError):
    """A pickled numpy object numpy would build unsafely (nothing built).

    Args:
        what (str): The refused object and why.
    """

    def __init__(self, what: str) -> None:
        super().__init__(what)
        self.qualname = what


@functools.lru_cache(maxsize=1)
def _numpy_functions() -> Tuple[Any, Any, Any]:
    """numpy's ``_reconstruct``, ``scalar`` and ``_frombuffer``."""
    core = numpy_core()
    multiarray = importlib.import_module(f'{core}.multiarray')
    numeric = importlib.import_module(f'{core}.numeric')
    return (multiarray._reconstruct, multiarray.scalar,
            numeric._frombuffer)


def plain_dtype(dtype: Any) -> np.dtype:
    """``dtype`` if it is a dtype of :data:`KINDS` as numpy constructs it.

    Raises:
        UnsafeArrayError: For another object, an object, structured,
            subarray or datetime dtype, or one whose flags or sizes differ
            from a dtype constructed from its type string.
    """
    if not isinstance(dtype, np.dtype):
        raise UnsafeArrayError(
            f'a numpy array or scalar whose dtype is a '
            f'{type(dtype).__qualname__}, not a numpy dtype')
    if (dtype.kind not in KINDS or dtype.fields is not None
            or dtype.subdtype is not None or dtype.hasobject):
        raise UnsafeArrayError(
            f'a numpy dtype {dtype.str!r}, not a plain one ({_PLAIN})')
    fresh = np.dtype(dtype.str)
    if (type(dtype), dtype.flags, dtype.itemsize, dtype.alignment,
            dtype.byteorder) != (type(fresh), fresh.flags, fresh.itemsize,
                                 fresh.alignment, fresh.byteorder):
        raise UnsafeArrayError(
            f'a numpy dtype {dtype.str!r} whose flags or sizes differ from '
            'those numpy gives it')
    return dtype


def new_dtype(obj: Any, align: Any = False, copy: Any = False) -> np.dtype:
    """``numpy.dtype(obj, align, copy)`` of a pickle: a new plain dtype.

    Raises:
        UnsafeArrayError: For anything but a type string of a plain kind.
    """
    del copy  # always a copy: BUILD may set its byte order
    if not isinstance(obj, str) or align not in (False, 0):
        raise UnsafeArrayError(
            f'numpy.dtype({str(obj)[:40]!r}, align={str(align)[:10]}), not '
            f'the type string of a plain dtype ({_PLAIN})')
    try:
        dtype = np.dtype(obj)
    except (TypeError, ValueError) as err:
        raise UnsafeArrayError(f'numpy.dtype({obj[:40]!r}) ({err})') from None
    if (dtype.kind not in KINDS or dtype.fields is not None
            or dtype.subdtype is not None or dtype.hasobject):
        raise UnsafeArrayError(
            f'numpy.dtype({obj[:40]!r}), not a plain dtype ({_PLAIN})')
    return np.dtype(obj, copy=True)


def _build_dtype(dtype: np.dtype, state: Any) -> None:
    """Check a dtype's pickled state; set its byte order if it differs.

    Raises:
        UnsafeArrayError: If the state is not that of a freshly
            constructed dtype of the same type in some byte order.
    """
    if not (isinstance(state, tuple) and len(state) in (8, 9)
            and state[1] in _BYTE_ORDERS):
        raise UnsafeArrayError(f'a numpy dtype {dtype.str!r} with a state '
                               'numpy does not write')
    target = np.dtype(dtype.str).newbyteorder(state[1])
    expected = target.__reduce__()[2]
    if state[1:8] != expected[1:8] or state[8:] not in ((), (None, )):
        raise UnsafeArrayError(
            f'a numpy dtype {dtype.str!r} whose pickled state {state!r} '
            f'differs from a fresh one ({expected!r}): its flags or sizes '
            'were altered')
    if dtype.__reduce__()[2][1:8] != expected[1:8]:
        np.dtype.__setstate__(dtype, expected)


def _shape(shape: Any) -> Tuple[int, ...]:
    """A shape of non-negative Python ints, or UnsafeArrayError."""
    if not (isinstance(shape, tuple) and all(
            type(n) is int and n >= 0 for n in shape)):
        raise UnsafeArrayError(f'a numpy array of shape {str(shape)[:60]}')
    return shape


def _raw_bytes(raw: Any, shape: Tuple[int, ...], dtype: np.dtype) -> None:
    """Check that ``raw`` holds exactly the array's bytes."""
    if type(raw) not in (bytes, bytearray):
        raise UnsafeArrayError(
            f'a numpy array whose data is a {type(raw).__qualname__} (only '
            'bytes are allowed)')
    expected = math.prod(shape) * dtype.itemsize
    if len(raw) != expected:
        raise UnsafeArrayError(
            f'a numpy array of shape {shape} and dtype {dtype.str!r} with '
            f'{len(raw)} bytes of data instead of {expected}')


class _NdarrayMarker:
    """Stands for ``numpy.ndarray`` in a pickle: ``_reconstruct``'s first
    argument, not callable."""

    def __repr__(self) -> str:
        return 'ndarray'


NDARRAY = _NdarrayMarker()


def new_array(subtype: Any, shape: Any, typecode: Any) -> np.ndarray:
    """``_reconstruct(ndarray, (0,), b'b')``: an empty array to BUILD.

    Raises:
        UnsafeArrayError: For another type or arguments (subclasses of
            ``ndarray`` are not allowed).
    """
    if subtype is not NDARRAY or shape != (0, ) or typecode != b'b':
        raise UnsafeArrayError(
            f'_reconstruct({subtype!r}, {str(shape)[:40]}, '
            f'{str(typecode)[:20]}) (only numpy.ndarray is allowed)')
    return _numpy_functions()[0](np.ndarray, (0, ), b'b')


def _build_array(array: np.ndarray, state: Any) -> None:
    """Check an array's pickled state, then let numpy set it.

    Raises:
        UnsafeArrayError: If the array is not a new one of
            :func:`new_array`, or the state is not a version-1 state of a
            plain dtype with exactly the array's bytes.
    """
    if (type(array) is not np.ndarray or array.shape != (0, )
            or array.dtype != np.int8 or not array.flags.owndata):
        raise UnsafeArrayError('BUILD (setting the state) of a numpy array '
                               'that is not a new one')
    if not (isinstance(state, tuple) and len(state) == 5 and state[0] == 1
            and state[3] in (False, True)):
        raise UnsafeArrayError('a numpy array with a state numpy does not '
                               'write')
    _, shape, dtype, fortran, raw = state
    shape, dtype = _shape(shape), plain_dtype(dtype)
    _raw_bytes(raw, shape, dtype)
    array.__setstate__((1, shape, dtype, bool(fortran), bytes(raw)))


def build(obj: Any, state: Any) -> None:
    """``BUILD`` of a numpy dtype or array, checked (see the module doc).

    Args:
        obj (numpy.dtype | numpy.ndarray): What the pickle sets the state
            of.
        state: The pickled state.

    Raises:
        UnsafeArrayError: If the state is refused.
    """
    if isinstance(obj, np.dtype):
        _build_dtype(obj, state)
    else:
        _build_array(obj, state)


def new_scalar(dtype: Any, data: Any = None) -> np.generic:
    """numpy's ``scalar(dtype, data)``: a scalar of a plain dtype.

    Raises:
        UnsafeArrayError: For another dtype, or data that is not exactly
            the scalar's bytes.
    """
    dtype = plain_dtype(dtype)
    _raw_bytes(data, (), dtype)
    return _numpy_functions()[1](dtype, bytes(data))


def new_frombuffer(buf: Any, dtype: Any, shape: Any,
                   order: Any) -> np.ndarray:
    """numpy's ``_frombuffer`` (pickle protocol 5), checked.

    Raises:
        UnsafeArrayError: For a buffer other than ``bytes`` /
            ``bytearray``, another dtype, shape or order, or a buffer of
            another size.
    """
    shape, dtype = _shape(shape), plain_dtype(dtype)
    _raw_bytes(buf, shape, dtype)
    if order not in ('C', 'F'):
        raise UnsafeArrayError(f'a numpy array of order {str(order)[:10]}')
    return _numpy_functions()[2](buf, dtype, shape, order)


#: What the restricted unpicklers resolve numpy's names to.
CONSTRUCTORS: Dict[str, Any] = {
    'numpy.dtype': new_dtype,
    'numpy.ndarray': NDARRAY,
    f'{numpy_core()}.multiarray._reconstruct': new_array,
    f'{numpy_core()}.multiarray.scalar': new_scalar,
    f'{numpy_core()}.numeric._frombuffer': new_frombuffer,
}

__all__ = [
    'CONSTRUCTORS', 'KINDS', 'NDARRAY', 'UnsafeArrayError', 'build',
    'new_array', 'new_dtype', 'new_frombuffer', 'new_scalar', 'numpy_core',
    'plain_dtype'
]
