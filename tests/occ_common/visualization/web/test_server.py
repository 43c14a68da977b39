"""The viewer's HTTP server, spoken to with urllib on 127.0.0.1."""
import gzip
import json
import urllib.error
import urllib.request

import numpy as np
import pytest

from projects.occ_common.visualization.web import (SampleCache, ViewerServer,
                                                   encode_sample,
                                                   unpack_message, viewer_meta)


def _encode(index):
    """Sample ``index``: a 2 x 2 x 1 grid with ``index + 1`` car voxels and
    one 4 x 6 black camera looking along +x."""
    gt = np.zeros((2, 2, 1), dtype=np.uint8)
    gt.ravel()[:index + 1] = 4
    lidar2img = np.eye(4)[None]
    lidar2img[0, :3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    return encode_sample(dict(name=f's{index}', pc_range=[0] * 3 + [2] * 3,
                              voxel_size=[1, 1, 2], gt_occ=gt,
                              images=np.zeros((1, 4, 6, 3), np.uint8),
                              lidar2img=lidar2img, cam_names=['CAM']),
                         num_classes=17, empty_label=0)


@pytest.fixture
def server():
    calls = []

    def encode(index):
        calls.append(index)
        return _encode(index)

    server = ViewerServer(viewer_meta(('empty', ) + ('c', ) * 16, 0, 3),
                          encode, 'console.log("viewer")', port=0)
    server.calls = calls
    server.start_background()
    yield server
    server.shutdown()
    server.server_close()


def _get(server, path, gz=True):
    request = urllib.request.Request(
        server.url + path.lstrip('/'),
        headers={'Accept-Encoding': 'gzip'} if gz else {})
    with urllib.request.urlopen(request, timeout=10) as response:
        body = response.read()
        if response.headers.get('Content-Encoding') == 'gzip':
            body = gzip.decompress(body)
        return response.headers, body


def test_routes(server):
    """The page refers to the script; the script, the dataset's meta, a
    sample's message (gzip-encoded on request, plain otherwise) and its
    camera JPEG come back; each sample is encoded once, however often it is
    asked for."""
    _, page = _get(server, '/')
    assert b'<script src="viewer.js">' in page
    headers, script = _get(server, '/viewer.js')
    assert script == b'console.log("viewer")'
    assert headers['Content-Encoding'] == 'gzip'
    assert json.loads(_get(server, '/api/meta.json')[1])['num_samples'] == 3
    headers, message = _get(server, '/api/sample/2.bin')
    assert headers['Content-Encoding'] == 'gzip'
    header, arrays = unpack_message(message)
    assert header['name'] == 's2' and header['counts']['gt'] == 3
    assert _get(server, '/api/sample/2.bin', gz=False)[1] == message
    headers, jpeg = _get(server, '/api/sample/2/camera/0.jpg')
    assert headers['Content-Type'] == 'image/jpeg' and jpeg[:2] == b'\xff\xd8'
    assert server.calls == [2]
    assert server.cache.sizes[2]['message'] == len(message)


@pytest.mark.parametrize('path,text', [
    ('/api/sample/3.bin', 'sample 3 is out of range: there are 3'),
    ('/api/sample/0/camera/1.jpg', 'sample 0 has 1 cameras, not 2'),
    ('/etc/passwd', 'no such page: /etc/passwd'),
])
def test_not_found(server, path, text):
    with pytest.raises(urllib.error.HTTPError) as caught:
        _get(server, path)
    assert caught.value.code == 404
    assert text in caught.value.read().decode()


def test_a_failing_sample_is_a_500_naming_it(server):
    def broken(index):
        raise ValueError(f'sample {index}: labels out of range')

    server.cache.encode = broken
    with pytest.raises(urllib.error.HTTPError) as caught:
        _get(server, '/api/sample/1.bin')
    assert caught.value.code == 500
    assert 'sample 1: labels out of range' in caught.value.read().decode()


def test_cache_keeps_the_last_samples():
    """Size 2: after 0, 1, 2 the first is encoded again; 2 is not."""
    calls = []
    cache = SampleCache(lambda i: calls.append(i) or _encode(i), 3, size=2)
    for index in (0, 1, 2, 2, 0):
        cache.get(index)
    assert calls == [0, 1, 2, 0]
