"""Tell the training dataset the epoch its augmentations are seeded with.

See :mod:`projects.occ_common.datasets.augmentation_seed`: each sample's
augmentation is drawn from ``(runner.seed, epoch, index)``, so a resumed
run repeats an uninterrupted one exactly.
"""
from typing import Iterator

from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook


def _datasets(dataset) -> Iterator:
    """``dataset`` and every dataset wrapped inside it."""
    yield dataset
    for inner in getattr(dataset, 'datasets', None) or ():
        yield from _datasets(inner)
    inner = getattr(dataset, 'dataset', None)
    if inner is not None:
        yield from _datasets(inner)


@HOOKS.register_module()
class AugmentationSeedHook(Hook):
    """Call ``set_augmentation_seed(seed, epoch)`` before every epoch.

    Listed in ``custom_hooks`` of ``configs/_base_/default_runtime.py``;
    datasets without the method (and wrappers) are left as they are.
    """

    priority = 'NORMAL'

    def before_train_epoch(self, runner) -> None:
        """Seed the augmentations of the coming epoch."""
        for dataset in _datasets(runner.train_dataloader.dataset):
            setter = getattr(dataset, 'set_augmentation_seed', None)
            if setter is not None:
                setter(runner.seed, runner.epoch)
