"""A tiny synthetic nuScenes world for tests, generated once per root.

``make_tiny_world(root)`` writes (in about two seconds) one scene of two key
frames with 160x90 images and ~1.6k LiDAR points per sweep, in the full
nuScenes / SurroundOcc / Occ3D layout of
:func:`projects.occ_common.synthetic.generate_synthetic_nuscenes`.
Calling it again with the same arguments on the same root reuses the world
(unless the generator's code changed), so a session-scoped fixture can share
it::

    @pytest.fixture(scope='session')
    def tiny_root(tmp_path_factory):
        return make_tiny_world(str(tmp_path_factory.mktemp('tiny_world')))

Other arguments of the generator can be overridden, e.g.
``make_tiny_world(root, num_scenes=2)`` for a clear day scene and a rainy
night scene. Besides the nuScenes files, the root holds what a test needs to
check against the truth: ``synthetic.camera_label_path(image_filename)``
names each image's per-pixel raw lidarseg class map, and
``synthetic.load_world(root, 'scene-0001')`` returns a scene's boxes and
ground layout.
"""
import glob
import hashlib
import json
import os.path as osp

from projects.occ_common import synthetic
from projects.occ_common.synthetic import (META_PATH,
                                           generate_synthetic_nuscenes)

#: Generator arguments of the tiny world.
TINY_WORLD_DEFAULTS = dict(num_scenes=1, samples_per_scene=2,
                           sweeps_per_sample=10, image_size=(160, 90),
                           version='v1.0-mini', seed=0, azimuth_bins=80)

_STAMP = osp.join('synthetic_gt', 'tiny_world.json')


def _normalise(params: dict) -> dict:
    """JSON round trip, so tuples and lists compare equal."""
    return json.loads(json.dumps(params, sort_keys=True))


def _generator_digest() -> str:
    """Hash of the generator's sources: a changed generator never reuses a
    world written by an older one."""
    digest = hashlib.md5()
    folder = osp.dirname(synthetic.__file__)
    for path in sorted(glob.glob(osp.join(folder, '*.py'))):
        with open(path, 'rb') as f:
            digest.update(f.read())
    return digest.hexdigest()


def make_tiny_world(root: str, **overrides) -> str:
    """Generates (or reuses) a tiny synthetic nuScenes world under
    ``root``.

    Args:
        root (str): Dataset root; created if missing. A root holding a
            tiny world made with other arguments is regenerated; a root
            holding anything else is refused (FileExistsError).
        **overrides: Arguments of ``generate_synthetic_nuscenes`` that
            replace :data:`TINY_WORLD_DEFAULTS` (``out_dir`` and
            ``overwrite`` are managed here).

    Returns:
        str: ``root``.

    Raises:
        ValueError: If ``overrides`` holds ``out_dir`` or ``overwrite``.
    """
    for managed in ('out_dir', 'overwrite'):
        if managed in overrides:
            raise ValueError(f'make_tiny_world manages {managed!r}; pass '
                             'only generator options as overrides.')
    root = str(root)
    params = _normalise({**TINY_WORLD_DEFAULTS, **overrides})
    request = dict(params=params, generator=_generator_digest())
    stamp = osp.join(root, _STAMP)
    if osp.isfile(stamp) and osp.isfile(osp.join(root, META_PATH)):
        with open(stamp) as f:
            previous = json.load(f)
        with open(osp.join(root, META_PATH)) as f:
            complete = json.load(f).get('complete', False)
        if complete and previous == request:
            return root
    kwargs = dict(params)
    kwargs['image_size'] = tuple(kwargs['image_size'])
    generate_synthetic_nuscenes(
        root, overwrite=osp.isfile(osp.join(root, META_PATH)), **kwargs)
    with open(stamp, 'w') as f:
        json.dump(request, f, sort_keys=True)
    return root
