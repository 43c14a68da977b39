"""Restricted unpickling of every pickle the library reads.

Info files are what users download from other people, and checkpoints come
from model zoos; a plain pickle of either can run any code when it is
loaded. Both are read here with unpicklers that resolve only an explicit
list of globals (``module.name`` pairs, checked *before* anything is
imported) and refuse anything else by name, so nothing from a refused file
is executed:

* **Info files** (:func:`load_info_file`): builtin containers and scalars
  and numpy arrays, scalars and dtypes, which is all the converter (and
  mmdet3d's own info files) write. Python's C unpickler with a restricted
  ``find_class`` (info files of a full dataset are large; this library's
  own hold no numpy object). A file naming numpy is read again with the
  pure-Python unpickler, whose ``BUILD`` rebuilds numpy objects only
  through the checks of :mod:`.safe_numpy`: numpy's ``__setstate__``
  trusts the file, and allowed globals suffice to forge an object array.
* **Checkpoints** (:func:`load_checkpoint_file`): first the format
  (:mod:`.checkpoint_format`): a TorchScript archive, which ``torch.load``
  would hand to ``torch.jit.load`` and so run its code, and any file but
  a plain ``torch.save`` zip or legacy pickle are refused before torch
  reads them. Then ``torch.load(..., weights_only=False,
  pickle_module=CHECKPOINT_PICKLE)`` with the info-file list plus torch's
  tensor / storage rebuild functions, ``torch.Size``, dtypes,
  ``collections.OrderedDict`` and mmengine's ``HistoryBuffer`` (the
  message hub of a Runner checkpoint), on torch 2.0 ... 2.13 and both of
  torch's file formats. This unpickler is pickle's pure-Python one, as it
  must also restrict ``BUILD`` (setting an object's state) to checked
  numpy objects, ``HistoryBuffer`` instances and ``OrderedDict`` (a state
  dict's ``_metadata``): the Python functions on the list must not have
  their attributes rewritten. A checkpoint pickle holds only the
  structure (tensor data lies in separate records): this costs little.

``torch.load(weights_only=True)`` with ``add_safe_globals`` (torch >= 2.4)
is not used instead: its ``BUILD`` calls the ``__setstate__`` of any
allow-listed type with the file's state, for numpy dtypes exactly the call
a forged dtype abuses; ``getattr(HistoryBuffer, 'min')`` needs the tuple
form of ``add_safe_globals`` (newer torch) in a process-wide registry; and
its default list allows more tensor kinds (sparse, quantized, nested) than
a checkpoint holds.

A Runner checkpoint written by plain mmengine (every zoo checkpoint of
OpenMMLab) pickles the statistics methods of its ``HistoryBuffer``\\ s as
``builtins.getattr(HistoryBuffer, 'min')``. ``getattr`` is therefore
allowed with exactly that object and the statistic names ``HistoryBuffer``
registers, and with nothing else; the class-level registry of statistic
methods, which ``HistoryBuffer.__setstate__`` updates from the file, is
restored after every load, so a file cannot leave a method behind.

Checkpoints in torch's zip format are first checked record by record
against their CRC-32 (:mod:`.zip_integrity`), and the config text that
mmengine would run as code is removed from every checkpoint returned
(:mod:`.checkpoint_meta`): a plain string is nothing the unpickler can
refuse.

mmengine's ``CheckpointLoader`` (``load_from``, ``--resume``,
``init_cfg=dict(type='Pretrained')``, every URL scheme) is pointed at
:func:`load_checkpoint_file` by :func:`install_checkpoint_loader`
(:mod:`.checkpoint_schemes`).
"""
import _compat_pickle
import collections
import contextlib
import functools
import importlib
import io
import os
import os.path as osp
import pickle
import types
from typing import Any, BinaryIO, Callable, Dict, Iterator, Optional, Union

import numpy as np
import torch

from . import safe_numpy
from .checkpoint_format import LEGACY, TORCHSCRIPT, ZIP, checkpoint_format
from .checkpoint_meta import drop_config_text
from .safe_numpy import UnsafeArrayError, numpy_core
from .zip_integrity import DamagedRecordError, check_zip_records


class RefusedGlobalError(pickle.UnpicklingError):
    """A pickle names a global outside the allow-list (nothing was run).

    Args:
        qualname (str): ``module.name`` of the refused global, or a
            description of the refused operation.
    """

    def __init__(self, qualname: str) -> None:
        super().__init__(qualname)
        self.qualname = qualname


# numpy 2 pickles name ``numpy._core``, numpy 1 ``numpy.core``: a file from
# either loads under either (the objects are the same).
_NUMPY_ALIASES = {
    f'numpy.{core}.{module}': f'{numpy_core()}.{module}'
    for core in ('core', '_core') for module in ('multiarray', 'numeric')
}

#: Globals of an info file: builtin containers and scalars, numpy arrays,
#: scalars and dtypes (resolved to the checked constructors of
#: :data:`.safe_numpy.CONSTRUCTORS`). ``_codecs.encode`` is how pickle
#: protocol 2 writes ``bytes`` (``bytes()`` the empty ones, the data of
#: an empty array), ``_frombuffer`` how protocol 5 writes arrays.
INFO_GLOBALS = frozenset({
    'builtins.set', 'builtins.frozenset', 'builtins.bytearray',
    'builtins.bytes', 'builtins.complex', 'builtins.slice', '_codecs.encode',
    *safe_numpy.CONSTRUCTORS
})


def _tensor_globals() -> frozenset:
    """torch's rebuild functions of dense tensors and parameters."""
    names = {
        'torch._utils._rebuild_tensor', 'torch._utils._rebuild_tensor_v2',
        'torch._utils._rebuild_tensor_v3', 'torch._utils._rebuild_parameter',
        'torch._utils._rebuild_parameter_with_state',
        'torch._tensor._rebuild_from_type_v2', 'torch.Size', 'torch.Tensor',
        'torch.device', 'torch.nn.parameter.Parameter',
        'collections.OrderedDict', 'collections.Counter'
    }
    # Only those this torch has (``_rebuild_tensor_v3``: torch >= 2.1).
    return frozenset(
        name for name in names
        if hasattr(importlib.import_module(name.rsplit('.', 1)[0]),
                   name.rsplit('.', 1)[1]))


#: Globals of a checkpoint besides :data:`INFO_GLOBALS` (``Counter``: the
#: milestones of mmengine's MultiStepLR state). Storage types
#: (``torch.FloatStorage`` ...) never reach the allow-list: torch.load's
#: own unpickler maps every name containing ``Storage`` to a dtype tag.
#: ``builtins.getattr`` is allowed only as :func:`_history_buffer_getattr`.
CHECKPOINT_GLOBALS = frozenset({
    *_tensor_globals(), 'mmengine.logging.history_buffer.HistoryBuffer',
    'builtins.getattr'
})


#: ``torch.float32`` ... by name, looked up without touching other names.
_TORCH_DTYPES = {
    name: value
    for name, value in vars(torch).items() if isinstance(value, torch.dtype)
}


@functools.lru_cache(maxsize=1)
def _history_buffer() -> type:
    """mmengine's ``HistoryBuffer`` class, its default statistics
    registered (the first instance registers them)."""
    from mmengine.logging.history_buffer import HistoryBuffer
    HistoryBuffer()
    return HistoryBuffer


def statistic_names() -> frozenset:
    """Names of the statistics methods defined on ``HistoryBuffer``.

    Returns:
        frozenset[str]: The registered names that are functions of the
        class itself (``min``, ``max``, ``current``, ``mean`` in mmengine
        0.10.7).
    """
    buffer = _history_buffer()
    return frozenset(
        name for name, method in buffer._statistics_methods.items()
        if vars(buffer).get(name) is method)


def _history_buffer_getattr(obj: Any, name: str) -> Callable:
    """``getattr`` of a zoo checkpoint: ``HistoryBuffer`` statistics only.

    Raises:
        RefusedGlobalError: For any other object or attribute name.
    """
    buffer = _history_buffer()
    if obj is not buffer or name not in statistic_names():
        what = getattr(obj, '__qualname__', None) or repr(obj)[:60]
        raise RefusedGlobalError(
            f'builtins.getattr({what}, {name!r}) (getattr is allowed only on'
            f' HistoryBuffer and its statistics {sorted(statistic_names())})'
        )
    return getattr(obj, name)


def _resolve(qualname: str) -> Any:
    """The object of an allowed ``module.name`` (``builtins.getattr`` and
    numpy's names: the restricted ones)."""
    if qualname == 'builtins.getattr':
        return _history_buffer_getattr
    if qualname in safe_numpy.CONSTRUCTORS:
        return safe_numpy.CONSTRUCTORS[qualname]
    module, name = qualname.rsplit('.', 1)
    return getattr(importlib.import_module(module), name)


def _find_allowed(module: str,
                  name: str,
                  allowed: frozenset,
                  torch_dtypes: bool = False) -> Any:
    """``find_class`` of the restricted unpicklers.

    Args:
        module (str): Module named by the pickle.
        name (str): Global named by the pickle.
        allowed (frozenset): Allowed ``module.name`` strings.
        torch_dtypes (bool): Also allow ``torch.<dtype>`` (``torch.float32``
            ...). Defaults to False.

    Returns:
        The global.

    Raises:
        RefusedGlobalError: If it is not allowed; nothing was imported.
    """
    # Protocol 2 (torch.save's default) writes Python 2 names
    # (``__builtin__``); map them as pickle does. A Python 3 name is never
    # in these tables.
    if (module, name) in _compat_pickle.NAME_MAPPING:
        module, name = _compat_pickle.NAME_MAPPING[(module, name)]
    module = _compat_pickle.IMPORT_MAPPING.get(module, module)
    module = _NUMPY_ALIASES.get(module, module)
    qualname = f'{module}.{name}'
    if qualname in allowed:
        return _resolve(qualname)
    if module == 'torch' and torch_dtypes and name in _TORCH_DTYPES:
        return _TORCH_DTYPES[name]
    raise RefusedGlobalError(qualname)


class _NumpyInFile(Exception):
    """The C unpickler met a numpy name: read the file in pure Python."""


class InfoUnpickler(pickle.Unpickler):
    """C unpickler resolving only :data:`INFO_GLOBALS` but numpy's.

    It cannot check ``BUILD``: a numpy name raises :class:`_NumpyInFile`
    before anything of numpy is built, and :func:`load_info_file` reads
    the file again with :class:`CheckedUnpickler`.
    """

    def find_class(self, module: str, name: str) -> Any:
        """Resolve an allowed global or raise :class:`RefusedGlobalError`."""
        found = _find_allowed(module, name, INFO_GLOBALS)
        if any(found is value for value in safe_numpy.CONSTRUCTORS.values()):
            raise _NumpyInFile(f'{module}.{name}')
        return found


@contextlib.contextmanager
def _statistics_registry_restored() -> Iterator[None]:
    """Undo what a loaded ``HistoryBuffer`` registers class-wide.

    ``HistoryBuffer.__setstate__`` adds the file's ``statistics_methods``
    to the class-level registry; only the class's own methods under their
    own names are accepted, and the registry is restored either way.
    """
    registry = _history_buffer()._statistics_methods
    before = dict(registry)
    try:
        yield
        foreign = sorted(name for name, method in registry.items()
                         if before.get(name) is not method)
        if foreign:
            raise RefusedGlobalError(
                f'HistoryBuffer statistics methods {foreign} that are not '
                'the methods of HistoryBuffer')
    finally:
        registry.clear()
        registry.update(before)


class CheckedUnpickler(pickle._Unpickler):
    """Pure-Python unpickler checking globals and every ``BUILD``.

    Resolves :data:`INFO_GLOBALS`; ``BUILD`` of numpy dtypes and arrays
    goes through :func:`.safe_numpy.build`, of other objects only where
    :meth:`may_build` allows it (never, for info files).
    """

    _ALLOWED = INFO_GLOBALS
    _TORCH_DTYPES = False
    dispatch = dict(pickle._Unpickler.dispatch)

    def find_class(self, module: str, name: str) -> Any:
        """Resolve an allowed global or raise :class:`RefusedGlobalError`."""
        return _find_allowed(module, name, self._ALLOWED, self._TORCH_DTYPES)

    def may_build(self, inst: Any) -> bool:
        """Whether ``BUILD`` may set the state of ``inst`` (not numpy)."""
        return False

    def load_build(self) -> None:
        """``BUILD``: numpy checked, other types if :meth:`may_build`."""
        inst = self.stack[-2]  # the state is on top
        if isinstance(inst, (np.ndarray, np.dtype)):
            safe_numpy.build(inst, self.stack.pop())
            return
        if not self.may_build(inst):
            raise RefusedGlobalError(
                f'BUILD (setting the state) of a {type(inst).__qualname__}')
        super().load_build()

    dispatch[pickle.BUILD[0]] = load_build


class CheckpointUnpickler(CheckedUnpickler):
    """Pure-Python unpickler for checkpoints (see the module docstring).

    Resolves :data:`INFO_GLOBALS` and :data:`CHECKPOINT_GLOBALS`;
    ``BUILD`` also on ``HistoryBuffer`` instances and ``OrderedDict``
    objects.
    """

    _ALLOWED = INFO_GLOBALS | CHECKPOINT_GLOBALS
    _TORCH_DTYPES = True

    def may_build(self, inst: Any) -> bool:
        """``HistoryBuffer`` and ``OrderedDict`` (a state dict's
        ``_metadata``)."""
        return (isinstance(inst, _history_buffer())
                or type(inst) is collections.OrderedDict)

    def load(self) -> Any:
        """Unpickle, keeping ``HistoryBuffer``'s registry unchanged."""
        with _statistics_registry_restored():
            return super().load()


def _checkpoint_load(file, **kwargs) -> Any:
    """``pickle_module.load`` (torch's legacy format reads its header so)."""
    return CheckpointUnpickler(file, **kwargs).load()


#: The ``pickle_module`` handed to ``torch.load`` for checkpoints.
CHECKPOINT_PICKLE = types.SimpleNamespace(
    __name__=__name__ + '.CHECKPOINT_PICKLE',
    Unpickler=CheckpointUnpickler,
    load=_checkpoint_load,
    loads=lambda data, **kwargs: _checkpoint_load(io.BytesIO(data), **kwargs),
    UnpicklingError=pickle.UnpicklingError)


class UnsafeCheckpointError(RefusedGlobalError):
    """A checkpoint pickles a refused global; nothing from it was run."""


class CorruptFileError(ValueError):
    """A file is empty, truncated or not of the expected kind."""


def _check_file(path: str, what: str) -> None:
    if not osp.isfile(path):
        raise FileNotFoundError(f'{what} {path} can not be found.')
    if os.path.getsize(path) == 0:
        raise CorruptFileError(f'{what} {path} is empty (0 bytes).')


def load_info_file(path: str) -> Any:
    """Unpickle an info file, allowing only :data:`INFO_GLOBALS`.

    Args:
        path (str): The ``.pkl`` file.

    Returns:
        Any: Its content (a dict for info files of this library).

    Raises:
        FileNotFoundError: If ``path`` is not a file.
        RefusedGlobalError: If it names another global, or a numpy object
            numpy would build unsafely; the message names the file and
            what was refused, and nothing from it was executed.
        CorruptFileError: If it is empty, truncated or not a pickle.
    """
    _check_file(path, 'info file')
    with open(path, 'rb') as f:
        try:
            try:
                return InfoUnpickler(f).load()
            except _NumpyInFile:
                f.seek(0)
                return CheckedUnpickler(f).load()
        except UnsafeArrayError as err:
            raise RefusedGlobalError(
                f'Refusing to load info file {path}: it pickles '
                f'{err.qualname}. Nothing from it was executed.') from None
        except RefusedGlobalError as err:
            raise RefusedGlobalError(
                f'Refusing to load info file {path}: it pickles '
                f'{err.qualname}, which an info file never holds (only '
                'builtin containers and scalars and numpy arrays are '
                'allowed). Nothing from it was executed.') from None
        except Exception as err:  # noqa: BLE001 - any decode failure
            raise CorruptFileError(
                f'info file {path} is truncated or not a pickle '
                f'({type(err).__name__}: {err}); re-create it with '
                'tools/create_data.py --overwrite.') from None


MapLocation = Optional[Union[str, Callable, torch.device, Dict]]


def load_checkpoint_file(filename: str,
                         map_location: MapLocation = None) -> Any:
    """Load a local checkpoint through the restricted unpickler.

    Args:
        filename (str): Path of the checkpoint file.
        map_location (str | callable | torch.device | dict, optional): As
            for :func:`torch.load`. Defaults to None.

    Returns:
        dict: The checkpoint, without config text
        (:func:`~.checkpoint_meta.drop_config_text`).

    Raises:
        FileNotFoundError: If ``filename`` is not a file.
        UnsafeCheckpointError: If it is a TorchScript archive, or pickles
            a global outside the allow-list or a numpy object numpy would
            build unsafely; the message names the file and what was
            refused, and nothing from it was executed.
        CorruptFileError: If it is empty, truncated, not a checkpoint, or
            a record of its zip archive does not match its CRC-32.
    """
    filename = osp.expanduser(filename)
    _check_file(filename, 'checkpoint')
    with open(filename, 'rb') as f:
        return load_checkpoint_stream(f, filename, map_location)


def load_checkpoint_stream(file: BinaryIO,
                           name: str,
                           map_location: MapLocation = None) -> Any:
    """:func:`load_checkpoint_file` of an open file (a download in memory).

    The format and, for torch's zip format, every record's CRC-32
    (:mod:`.zip_integrity`) are checked on the same open file that
    ``torch.load`` then reads, so the file checked is the file loaded.
    The config text mmengine would run as code is removed from what is
    returned (:mod:`.checkpoint_meta`).

    Args:
        file (BinaryIO): Seekable, at its start.
        name (str): The file's name or URL, for the messages.
        map_location (str | callable | torch.device | dict, optional): As
            for :func:`torch.load`. Defaults to None.

    Returns:
        dict: The checkpoint.

    Raises:
        UnsafeCheckpointError: See :func:`load_checkpoint_file`.
        CorruptFileError: See :func:`load_checkpoint_file`.
    """
    kind, detail = checkpoint_format(file)
    if kind == TORCHSCRIPT:
        raise UnsafeCheckpointError(
            f'Refusing to load checkpoint {name}: it is a TorchScript '
            f'archive ({detail}), and TorchScript is not a checkpoint: '
            'torch.load would hand it to torch.jit.load, which runs the '
            'code it carries. Nothing from it was executed. Use the '
            'checkpoint (.pth of torch.save) of the model instead.')
    if kind not in (ZIP, LEGACY):
        raise CorruptFileError(
            f'checkpoint {name} is truncated or not a torch checkpoint '
            f'({detail}).')
    if kind == ZIP:
        try:
            check_zip_records(file, name)
        except DamagedRecordError as err:
            raise CorruptFileError(str(err)) from None
    checkpoint = _torch_load(file, name, map_location)
    drop_config_text(checkpoint, name)
    return checkpoint


def _torch_load(file: BinaryIO, name: str,
                map_location: MapLocation) -> Any:
    """``torch.load`` through :data:`CHECKPOINT_PICKLE`, its failures as
    the errors of :func:`load_checkpoint_stream`."""
    try:
        return torch.load(
            file,
            map_location=map_location,
            pickle_module=CHECKPOINT_PICKLE,
            weights_only=False)
    except UnsafeArrayError as err:
        raise UnsafeCheckpointError(
            f'Refusing to load checkpoint {name}: it pickles '
            f'{err.qualname}. Nothing from it was executed.') from None
    except RefusedGlobalError as err:
        raise UnsafeCheckpointError(
            f'Refusing to load checkpoint {name}: it pickles '
            f'{err.qualname}, which is outside the allow-list of tensors, '
            'containers, numpy arrays and mmengine message hubs. Nothing '
            'from it was executed. If you trust this file, load it with '
            'torch.load(weights_only=False) yourself and re-save its '
            'state_dict.') from None
    except (RuntimeError, EOFError, pickle.UnpicklingError, ValueError,
            KeyError, IndexError) as err:
        # Other RuntimeErrors (a CUDA checkpoint on a CPU machine, ...) are
        # not about the file's integrity: let them through.
        if isinstance(err, RuntimeError) and not any(
                word in str(err) for word in ('PytorchStreamReader', 'zip')):
            raise
        first_line = (str(err).splitlines() or [''])[0]
        raise CorruptFileError(
            f'checkpoint {name} is truncated or not a torch checkpoint '
            f'({type(err).__name__}: {first_line}).') from None


__all__ = [
    'CHECKPOINT_GLOBALS', 'CHECKPOINT_PICKLE', 'CorruptFileError',
    'INFO_GLOBALS', 'RefusedGlobalError', 'UnsafeArrayError',
    'UnsafeCheckpointError', 'load_checkpoint_file', 'load_checkpoint_stream',
    'load_info_file', 'statistic_names'
]
