"""Previous key-frame links of the info files, for temporal models.

A T-frame model (SDG-OCC's "T-frame consequent sequence", Sec. 3.1) needs,
for each key frame, the key frame before it in the same scene: its token
and what loading it takes (images with their calibration, the LiDAR file
and its calibration, the ego pose). The converter writes them into every
``data_list`` entry as ``prev_key_frame``; the first key frame of a scene
gets None, and readers repeat the frame itself there (as BEVDet4D does),
so a scene's start looks like a car that has not moved.
"""
from typing import Dict, List, Optional

#: The keys of an entry that ``prev_key_frame`` copies: enough to load the
#: frame's images and points and to align it with the ego pose.
LINK_KEYS = ('token', 'timestamp', 'ego2global', 'lidar_points', 'images')


def link_previous_key_frames(entries: List[dict]) -> List[dict]:
    """Add ``prev_key_frame`` to every entry (in place).

    Args:
        entries (list[dict]): ``data_list`` entries with ``token``, ``prev``
            (the previous key frame's token, '' at a scene's start) and the
            :data:`LINK_KEYS`.

    Returns:
        list[dict]: ``entries``; each has ``prev_key_frame``, a dict of the
        :data:`LINK_KEYS` of the previous key frame, or None at a scene's
        start.

    Raises:
        ValueError: If an entry's ``prev`` names a key frame that is not
            among ``entries`` (a scene split across info files).
    """
    by_token: Dict[str, dict] = {e['token']: e for e in entries}
    for entry in entries:
        prev: Optional[str] = entry.get('prev') or None
        if prev is None:
            entry['prev_key_frame'] = None
            continue
        if prev not in by_token:
            raise ValueError(
                f'sample {entry["token"]} of scene '
                f'{entry.get("scene_name")}: its previous key frame {prev} '
                'is not converted with it; a scene must be whole in one '
                'split')
        source = by_token[prev]
        entry['prev_key_frame'] = {k: source[k] for k in LINK_KEYS}
    return entries
