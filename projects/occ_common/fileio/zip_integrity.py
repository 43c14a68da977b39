"""The CRC-32 of every record of a checkpoint's zip archive, checked.

``torch.save`` stores each record of its zip format with the CRC-32 of its
bytes, and torch's reader never compares it: one flipped bit in a tensor's
record loaded without a word and took a model's IoU from 3.74 to 0.00.
:func:`check_zip_records` reads every record through Python's
``zipfile``, which compares each CRC at the record's end, before
``torch.load`` reads the file. Reading a checkpoint twice costs one more
pass at the disk's speed (the CRC runs at over 1 GB/s in C).

torch's legacy format (a plain pickle followed by raw storages) carries no
checksum: a damaged legacy file is refused only where its pickle breaks.
"""
import zipfile
from typing import BinaryIO

#: Bytes read at a time.
_CHUNK = 1 << 22


class DamagedRecordError(ValueError):
    """A record of a zip archive does not match its stored CRC-32.

    Args:
        message (str): Names the file and the record.
        record (str): The damaged record's name.
    """

    def __init__(self, message: str, record: str) -> None:
        super().__init__(message)
        self.record = record


def check_zip_records(file: BinaryIO, name: str) -> int:
    """Compare every record of a zip archive with its CRC-32.

    Args:
        file (BinaryIO): The archive, seekable; it is left at its start.
        name (str): The file, for the message.

    Returns:
        int: The number of records checked.

    Raises:
        DamagedRecordError: Naming the file and the first record whose
            bytes or headers do not match (a flipped bit, a record cut
            short).
    """
    record = '(the central directory)'
    try:
        with zipfile.ZipFile(file) as archive:
            records = archive.infolist()
            for info in records:
                record = info.filename
                with archive.open(info) as member:
                    while member.read(_CHUNK):
                        pass
    except (zipfile.BadZipFile, OSError, EOFError, ValueError,
            NotImplementedError) as err:
        raise DamagedRecordError(
            f'checkpoint {name} is damaged: its record {record} does not '
            f'match its CRC-32 or header ({err}); the file changed after '
            'torch.save wrote it (a failing disk, an interrupted copy). '
            'Copy or download it again.', record) from None
    finally:
        file.seek(0)
    return len(records)


__all__ = ['DamagedRecordError', 'check_zip_records']
