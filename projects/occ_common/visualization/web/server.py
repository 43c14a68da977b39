"""The viewer's HTTP server: one port, the standard library only.

It serves the page, the bundled script and, per sample, the message of
:func:`~.scene_payload.encode_sample` (gzip-compressed when the browser
accepts it, as every browser does) and the camera JPEGs. Samples are
encoded on first request and the last few kept. It binds to 127.0.0.1 by
default: from a laptop, forward the port over SSH (``ssh -L 8765:localhost:
8765 gpu-box``, docs/visualization.md) instead of opening it to the network.
"""
import collections
import gzip
import json
import re
import threading
import traceback
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Callable, Dict, List, Tuple

from .page import served_page

#: ``index -> (message, camera JPEGs)``.
Encoder = Callable[[int], Tuple[bytes, List[bytes]]]

_SAMPLE = re.compile(r'^/api/sample/(\d+)\.bin$')
_CAMERA = re.compile(r'^/api/sample/(\d+)/camera/(\d+)\.jpg$')


class SampleCache:
    """The encoded samples, each made once while it stays among the last
    ``size`` asked for; one encoding at a time (a model or a data pipeline
    is not made for concurrent calls).

    Args:
        encode (Encoder): Makes sample ``index``'s message and JPEGs.
        num_samples (int): Valid indices are ``0 .. num_samples - 1``.
        size (int): Samples kept. Defaults to 8.
    """

    def __init__(self, encode: Encoder, num_samples: int, size: int = 8):
        self.encode = encode
        self.num_samples = num_samples
        self.size = size
        self._items: 'collections.OrderedDict' = collections.OrderedDict()
        self._lock = threading.Lock()
        #: ``index -> dict(message, message_gzip, images)`` in bytes, of
        #: every sample served (for the measurements of the docs).
        self.sizes: Dict[int, Dict[str, int]] = {}

    def get(self, index: int) -> Tuple[bytes, bytes, List[bytes]]:
        """The message, its gzip and the JPEGs of sample ``index``.

        Raises:
            IndexError: If ``index`` is out of range.
        """
        if not 0 <= index < self.num_samples:
            raise IndexError(f'sample {index} is out of range: there are '
                             f'{self.num_samples} (0..'
                             f'{self.num_samples - 1})')
        with self._lock:
            if index in self._items:
                self._items.move_to_end(index)
                return self._items[index]
            message, jpegs = self.encode(index)
            item = (message, gzip.compress(message, 6, mtime=0), jpegs)
            self._items[index] = item
            while len(self._items) > self.size:
                self._items.popitem(last=False)
            self.sizes[index] = dict(
                message=len(message), message_gzip=len(item[1]),
                images=sum(len(j) for j in jpegs))
            return item


def make_handler(meta: Dict, cache: SampleCache, script: str,
                 title: str, quiet: bool = True):
    """The request handler class of one viewer.

    Args:
        meta (dict): :func:`~.scene_payload.viewer_meta`.
        cache (SampleCache): The samples.
        script (str): :func:`~.bundle.viewer_script`.
        title (str): The page's title.
        quiet (bool): Log no request lines. Defaults to True.

    Returns:
        type: A ``BaseHTTPRequestHandler`` subclass.
    """
    page = served_page(title).encode()
    script_gz = gzip.compress(script.encode(), 6, mtime=0)
    meta_json = json.dumps(meta).encode()

    class Handler(BaseHTTPRequestHandler):
        protocol_version = 'HTTP/1.1'

        def log_message(self, format, *args):  # noqa: A002 (upstream name)
            if not quiet:
                super().log_message(format, *args)

        def _send(self, status, body: bytes, kind: str,
                  gzipped: bool = False) -> None:
            self.send_response(status)
            self.send_header('Content-Type', kind)
            self.send_header('Content-Length', str(len(body)))
            self.send_header('Cache-Control', 'no-store')
            if gzipped:
                self.send_header('Content-Encoding', 'gzip')
            self.end_headers()
            if self.command != 'HEAD':
                self.wfile.write(body)

        def _accepts_gzip(self) -> bool:
            return 'gzip' in self.headers.get('Accept-Encoding', '')

        def do_HEAD(self):  # noqa: N802 (http.server's name)
            self.do_GET()

        def do_GET(self):  # noqa: N802 (http.server's name)
            path = self.path.split('?', 1)[0]
            try:
                self._route(path)
            except IndexError as err:
                self._send(HTTPStatus.NOT_FOUND, str(err).encode(),
                           'text/plain; charset=utf-8')
            except Exception as err:  # a sample that fails: say which
                traceback.print_exc()
                self._send(HTTPStatus.INTERNAL_SERVER_ERROR,
                           f'{type(err).__name__}: {err}'.encode(),
                           'text/plain; charset=utf-8')

        def _route(self, path: str) -> None:
            gz = self._accepts_gzip()
            if path in ('/', '/index.html'):
                self._send(HTTPStatus.OK, page, 'text/html; charset=utf-8')
            elif path == '/viewer.js':
                self._send(HTTPStatus.OK, script_gz if gz else
                           script.encode(), 'text/javascript', gz)
            elif path == '/api/meta.json':
                self._send(HTTPStatus.OK, meta_json, 'application/json')
            elif _SAMPLE.match(path):
                message, packed, _ = cache.get(
                    int(_SAMPLE.match(path).group(1)))
                self._send(HTTPStatus.OK, packed if gz else message,
                           'application/octet-stream', gz)
            elif _CAMERA.match(path):
                index, camera = (int(v) for v in _CAMERA.match(path).groups())
                jpegs = cache.get(index)[2]
                if not 0 <= camera < len(jpegs):
                    raise IndexError(f'sample {index} has {len(jpegs)} '
                                     f'cameras, not {camera + 1}')
                self._send(HTTPStatus.OK, jpegs[camera], 'image/jpeg')
            else:
                raise IndexError(f'no such page: {path}')

    return Handler


class ViewerServer(ThreadingHTTPServer):
    """The viewer on ``host:port`` (port 0: any free port).

    Args:
        meta (dict): :func:`~.scene_payload.viewer_meta`.
        encode (Encoder): Makes a sample's message and JPEGs.
        script (str): :func:`~.bundle.viewer_script`.
        host (str): Address to bind. Defaults to '127.0.0.1'.
        port (int): Port. Defaults to 8765.
        title (str): The page's title. Defaults to 'occupancy viewer'.
        cache_size (int): Encoded samples kept. Defaults to 8.
        quiet (bool): Log no request lines. Defaults to True.
    """

    daemon_threads = True

    def __init__(self, meta: Dict, encode: Encoder, script: str,
                 host: str = '127.0.0.1', port: int = 8765,
                 title: str = 'occupancy viewer', cache_size: int = 8,
                 quiet: bool = True) -> None:
        self.cache = SampleCache(encode, meta['num_samples'], cache_size)
        super().__init__((host, port),
                         make_handler(meta, self.cache, script, title, quiet))

    @property
    def url(self) -> str:
        """str: The page's address, as the server sees it."""
        host, port = self.server_address[:2]
        return f'http://{host}:{port}/'

    def start_background(self) -> threading.Thread:
        """Serve from a daemon thread (tests, notebooks); stop with
        ``shutdown()`` and ``server_close()``."""
        thread = threading.Thread(target=self.serve_forever, daemon=True)
        thread.start()
        return thread
