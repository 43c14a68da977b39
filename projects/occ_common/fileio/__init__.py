"""Reading and writing the library's files safely: restricted unpickling
of checkpoints and info files (:mod:`.safe_pickle`, :mod:`.safe_numpy`),
the checkpoint formats and mmengine's schemes through that loader, and an
atomic local file backend."""
from .atomic_file_backend import (AtomicLocalBackend, atomic_write,
                                  register_atomic_backend)
from .checkpoint_schemes import install_checkpoint_loader
from .safe_pickle import (CHECKPOINT_GLOBALS, INFO_GLOBALS, CorruptFileError,
                          RefusedGlobalError, UnsafeCheckpointError,
                          load_checkpoint_file, load_info_file)

#: The name of :func:`load_checkpoint_file` in earlier versions.
load_weights_only = load_checkpoint_file

__all__ = [
    'AtomicLocalBackend', 'CHECKPOINT_GLOBALS', 'CorruptFileError',
    'INFO_GLOBALS', 'RefusedGlobalError', 'UnsafeCheckpointError',
    'atomic_write', 'install_checkpoint_loader', 'load_checkpoint_file',
    'load_info_file', 'load_weights_only', 'register_atomic_backend'
]
