"""The one check of a name taken from a file before it names a file.

Sample tokens, scene names and camera names come from info files and
nuScenes tables, which users download; a writer that puts one into a path
(``<out_dir>/<token>_info.pkl``) wrote outside its folder for a token of
``../x`` or ``/tmp/x``, and overwrote what was there. Every writer (and
reader) that builds a path from such a name passes it through
:func:`safe_file_name` first; ``tests/occ_common/fileio/test_safe_names.py``
lists them and fails on a new path built from a token, scene or camera name
without it.

A name is refused, never rewritten: replacing characters (``a/b`` ->
``a_b``) lets two samples share one file, and the second then overwrites
the first. The rule (an allow-list, so nothing depends on the platform's
separators, reserved names or case folding): 1 to 200 ASCII letters,
digits and ``. _ - +`` (nuScenes' LiDAR file names carry a ``+0800``),
not starting with ``.`` (hidden, ``..``) or ``-`` (read as an option by
command-line tools). nuScenes tokens (32 hex digits), scene names
(``scene-0061``), camera names (``CAM_FRONT``) and LiDAR file names all
pass; 200 leaves room for a suffix within the 255 bytes file systems take.
"""
import re

#: What :func:`safe_file_name` accepts (see the module docstring).
SAFE_NAME = re.compile(r'[A-Za-z0-9_+][A-Za-z0-9._+-]{0,199}')


def safe_file_name(value, what: str, source: str = '') -> str:
    """``value`` as text, if it can name a file inside a folder.

    Args:
        value (str | int): A token, scene or camera name, sample index ...
        what (str): What it is, for the message (``'sample token'``).
        source (str): Where it comes from (the info file), for the
            message. Defaults to ''.

    Returns:
        str: ``str(value)``, unchanged.

    Raises:
        ValueError: If it is empty, longer than 200 characters, holds a
            character other than ASCII letters, digits and ``. _ - +``
            (a path separator, ``..``, a space ...), or starts with ``.``
            or ``-``; naming the value, ``what`` and ``source``.
    """
    text = str(value)
    if SAFE_NAME.fullmatch(text):
        return text
    where = f'{source}: ' if source else ''
    raise ValueError(
        f'{where}{what} {text[:80]!r} cannot name a file: a name from a '
        'file must be 1 to 200 ASCII letters, digits and . _ - + and not '
        'start with . or - (it would otherwise write outside its folder or '
        'collide with another name).')


__all__ = ['SAFE_NAME', 'safe_file_name']
