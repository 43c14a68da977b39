"""Shared parts of the occupancy plugins, registered once.

Importing this package registers its datasets, transforms, models, metrics,
hooks and visualisers into the mmdet3d registries, and nothing else: the
restricted checkpoint loader (:mod:`.fileio.safe_pickle`) is installed by
``WeightsOnlyCheckpointHook`` before a Runner loads anything, and by
``tools/test.py``. Configs import it with
``custom_imports = dict(imports=['projects.occ_common'])``.

The model library: ``datasets``, ``transforms``, ``geometry``, ``models``,
``evaluation``, ``visualization``. Its harness, in mmdet3d's and
detectron2's rooms: ``fileio`` (restricted loading, checkpoint formats),
``engine`` (hooks, checkpoint checks, config checks, CPU ranks), ``apis``
(:func:`~.apis.init_model`), ``synthetic`` (the synthetic world and
batches), ``analysis`` (timing, op counting, tool runs), ``deployment``
(ONNX). ``utils`` holds runtime primitives only; ``testing`` holds helpers
of the tests, which no library module imports.
"""
from . import datasets, evaluation, models, transforms, visualization
from .engine import hooks

__all__ = [
    'datasets', 'evaluation', 'hooks', 'models', 'transforms',
    'visualization'
]
