"""The browser viewer: occupancy, LiDAR and cameras in 3D, served from the
machine that holds the data or exported as one HTML file.

:func:`encode_sample` turns a sample into a compact binary message,
:class:`ViewerServer` serves the page and the messages on one port,
:func:`export_html` writes a self-contained page; the page itself
(``static/*.js``, three.js) is bundled by :func:`viewer_script`.
``tools/misc/browse_occ.py`` is the command line; docs/visualization.md
compares the libraries this was built on.
"""
from .bundle import ViewerAssetsMissing, viewer_script
from .camera_frusta import frustum_corners
from .export import export_html
from .scene_payload import (encode_sample, error_grid, unpack_message,
                            viewer_meta)
from .server import SampleCache, ViewerServer

__all__ = [
    'SampleCache', 'ViewerAssetsMissing', 'ViewerServer', 'encode_sample',
    'error_grid', 'export_html', 'frustum_corners', 'unpack_message',
    'viewer_meta', 'viewer_script'
]
