"""Which kind of file a checkpoint is, found before ``torch.load`` sees it.

``torch.load`` chooses its reader from the first bytes of a file: a zip
archive (``PK\\x03\\x04``) is read record by record, anything else as
torch's legacy format (a protocol-2 pickle). A zip archive holding
``constants.pkl`` is a TorchScript archive, which ``torch.load(...,
weights_only=False)`` hands to ``torch.jit.load`` whatever
``pickle_module`` it was given: loading one runs the TorchScript code it
carries (its ``__setstate__`` methods), and no unpickler ever sees it.

:func:`checkpoint_format` tells the kinds apart with torch's own zip reader
(the one ``torch.load`` uses, so both see the same record names), so that
only plain checkpoints reach ``torch.load``: a zip archive whose records
are all those ``torch.save`` writes (``data.pkl``, ``data/<key>``,
``version``, ``byteorder`` and dot-files of metadata), or a file starting
like a pickle.
"""
import re
from typing import BinaryIO, List, Tuple

import torch

#: The kinds :func:`checkpoint_format` tells apart.
ZIP, LEGACY, TORCHSCRIPT, FOREIGN = ('zip', 'legacy', 'torchscript',
                                     'foreign')

#: How ``torch.load`` recognises its zip format (``_is_zipfile``).
ZIP_MAGIC = b'PK\x03\x04'

#: Records that only TorchScript archives (``torch.jit.save``) and mobile
#: ones (``_save_for_lite_interpreter``) hold: the code, its constants, the
#: bytecode and extra files.
_TORCHSCRIPT_RECORD = re.compile(
    r'^(constants\.pkl|bytecode\.pkl|(code|constants|extra)/.*)$')

#: Records that ``torch.save`` writes (torch 2.0 ... 2.13): the pickle, one
#: record a storage, the format version, the byte order, and metadata
#: dot-files (``.format_version``, ``.data/serialization_id``, ...).
_PLAIN_RECORD = re.compile(
    r'^(data\.pkl|version|byteorder|data/[^/]+|\.[^/]+|\.data/[^/]+)$')


def _records(file: BinaryIO) -> List[str]:
    """Record names of a zip archive, as ``torch.load`` reads them.

    Raises:
        RuntimeError | OSError: From torch's reader, if it is not a
            readable zip.
    """
    return list(torch._C.PyTorchFileReader(file).get_all_records())


def checkpoint_format(file: BinaryIO) -> Tuple[str, str]:
    """Which kind of file ``file`` is, as ``torch.load`` would read it.

    Args:
        file (BinaryIO): The open file, at its start; it is read, and left
            at its start again.

    Returns:
        tuple[str, str]: The kind and what showed it:

        * :data:`ZIP`: a zip archive of ``torch.save``'s records only;
        * :data:`LEGACY`: torch's legacy format (the file starts like a
          pickle of protocol 2 or above);
        * :data:`TORCHSCRIPT`: a TorchScript archive (the records that
          show it);
        * :data:`FOREIGN`: anything else, why (a damaged zip, unknown
          records, the first bytes).
    """
    head = file.read(len(ZIP_MAGIC))
    file.seek(0)
    if head != ZIP_MAGIC:
        if head[:1] == b'\x80':
            return LEGACY, 'a pickle'
        return FOREIGN, (f'neither a complete zip archive nor a legacy '
                         f'pickle; it starts with {head!r}')
    try:
        records = _records(file)
    except (RuntimeError, OSError) as err:
        # torch's reader raises OSError where a truncated archive's
        # central directory points past the end of the file.
        first_line = (str(err).splitlines() or [''])[0]
        return FOREIGN, f'a damaged zip archive: {first_line}'
    finally:
        file.seek(0)
    scripted = [name for name in records if _TORCHSCRIPT_RECORD.match(name)]
    if scripted:
        return TORCHSCRIPT, f'it holds {", ".join(sorted(scripted)[:3])}'
    if 'data.pkl' not in records:
        return FOREIGN, 'a zip archive without data.pkl'
    unknown = [name for name in records if not _PLAIN_RECORD.match(name)]
    if unknown:
        return FOREIGN, (f'a zip archive with records torch.save does not '
                         f'write: {", ".join(sorted(unknown)[:3])}')
    return ZIP, 'a zip archive of torch.save'


__all__ = [
    'FOREIGN', 'LEGACY', 'TORCHSCRIPT', 'ZIP', 'ZIP_MAGIC',
    'checkpoint_format'
]
