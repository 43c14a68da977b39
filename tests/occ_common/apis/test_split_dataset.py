"""build_split_dataset: both splits go through the test pipeline."""
import os.path as osp

import pytest
from mmengine.config import Config

from projects.occ_common.apis import build_split_dataset

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
TINY = osp.join(ROOT, 'configs', 'occ_cyl',
                'occcyl_tiny_1xb1-6e_surroundocc-nus-synthetic.py')


@pytest.mark.parametrize('split, ann_file', [
    ('val', 'nuscenes_occ_infos_val.pkl'),
    ('train', 'nuscenes_occ_infos_train.pkl'),
])
def test_split_keeps_its_samples_and_takes_the_test_pipeline(
        converted_tiny_world, split, ann_file):
    """The tiny world's one scene (2 key frames) is both splits; the train
    split's sample comes without the training augmentation (its
    MultiViewImageAug in test mode: no flip, no rotation)."""
    cfg = Config.fromfile(TINY)
    dataset = build_split_dataset(cfg, split, converted_tiny_world)
    assert osp.basename(dataset.ann_file) == ann_file and len(dataset) == 2
    augs = [t for t in dataset.pipeline.transforms
            if type(t).__name__ == 'MultiViewImageAug']
    assert len(augs) == 1 and augs[0].test_mode


def test_unknown_split_is_refused():
    with pytest.raises(ValueError, match="split must be 'val' or 'train'"):
        build_split_dataset(Config.fromfile(TINY), 'test')
