"""One self-contained HTML file of one or more samples: the viewer, three.js
and the data inside, nothing fetched, for mail or a report."""
import base64
import gzip
import os
import os.path as osp
from typing import Dict, List, Optional, Sequence, Tuple

from .page import exported_page


def embedded_sample(message: bytes, jpegs: Sequence[bytes]) -> Dict:
    """A sample as the exported page holds it.

    Args:
        message (bytes): :func:`~.scene_payload.encode_sample`'s message.
        jpegs (Sequence[bytes]): Its camera images.

    Returns:
        dict: ``message`` (base64 of the gzip-compressed message) and
        ``images`` (JPEG data URLs).
    """
    packed = gzip.compress(message, 9, mtime=0)
    return dict(
        message=base64.b64encode(packed).decode('ascii'),
        images=[
            'data:image/jpeg;base64,' + base64.b64encode(j).decode('ascii')
            for j in jpegs
        ])


def export_html(path: str,
                meta: Dict,
                samples: List[Tuple[bytes, List[bytes]]],
                script: str,
                title: str = 'occupancy',
                note: Optional[str] = None) -> Dict[str, int]:
    """Write the page of ``samples`` to ``path``.

    Args:
        path (str): The ``.html`` file; its folder is created.
        meta (dict): :func:`~.scene_payload.viewer_meta` (its
            ``num_samples`` is set to ``len(samples)``).
        samples (list[tuple[bytes, list[bytes]]]): Message and JPEGs of
            each sample.
        script (str): :func:`~.bundle.viewer_script`.
        title (str): The page's title. Defaults to 'occupancy'.
        note (str, optional): A comment at the top of the file. Defaults
            to None.

    Returns:
        dict[str, int]: Bytes of the file, of the script, of the messages
        (raw) and of the images.

    Raises:
        ValueError: If ``samples`` is empty.
    """
    if not samples:
        raise ValueError(f'{path}: no sample to export.')
    data = dict(meta=dict(meta, num_samples=len(samples), initial_index=0),
                samples=[embedded_sample(m, j) for m, j in samples])
    text = exported_page(title, script, data, note)
    folder = osp.dirname(osp.abspath(path))
    os.makedirs(folder, exist_ok=True)
    with open(path, 'w', encoding='utf-8') as f:
        f.write(text)
    return dict(
        file=len(text.encode('utf-8')),
        script=len(script.encode('utf-8')),
        messages=sum(len(m) for m, _ in samples),
        images=sum(len(j) for _, jpegs in samples for j in jpegs))
