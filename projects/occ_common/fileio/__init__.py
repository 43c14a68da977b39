"""Reading and writing the library's files safely: restricted unpickling
of checkpoints and info files (:mod:`.safe_pickle`, :mod:`.safe_numpy`),
the checkpoint formats and mmengine's schemes through that loader (record
CRCs checked, :mod:`.zip_integrity`; config text dropped,
:mod:`.checkpoint_meta`), a sample's input files read within limits
(:mod:`.input_files`), the one check of names from files before they name
a file (:mod:`.safe_names`), and an atomic local file backend."""
from .atomic_file_backend import (AtomicLocalBackend, atomic_write,
                                  register_atomic_backend)
from .checkpoint_schemes import install_checkpoint_loader
from .input_files import MAX_INPUT_BYTES, check_input_file, read_input_bytes
from .safe_names import safe_file_name
from .safe_pickle import (CHECKPOINT_GLOBALS, INFO_GLOBALS, CorruptFileError,
                          RefusedGlobalError, UnsafeCheckpointError,
                          load_checkpoint_file, load_info_file)

#: The name of :func:`load_checkpoint_file` in earlier versions.
load_weights_only = load_checkpoint_file

__all__ = [
    'AtomicLocalBackend', 'CHECKPOINT_GLOBALS', 'CorruptFileError',
    'INFO_GLOBALS', 'MAX_INPUT_BYTES', 'RefusedGlobalError',
    'UnsafeCheckpointError', 'atomic_write', 'check_input_file',
    'install_checkpoint_loader', 'load_checkpoint_file', 'load_info_file',
    'load_weights_only', 'read_input_bytes', 'register_atomic_backend',
    'safe_file_name'
]
