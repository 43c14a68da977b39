"""docs/customize_dataset.md's rig config example merges as it says.

Its python block is written out where the guide puts it (a folder beside
``configs/sdg_occ/``, here in a temporary copy of the path layout: the
``../sdg_occ/`` base made absolute) and loaded with mmengine: every
dataloader keeps the paper config's pipeline and gains the four cameras
and the data root.
"""
import os.path as osp
import re

from mmengine.config import Config

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))


def test_rig_config_example_merges(tmp_path):
    with open(osp.join(ROOT, 'docs', 'customize_dataset.md')) as f:
        guide = f.read()
    section = guide.split('## 2. A config')[1].split('\n## ')[0]
    (block, ) = re.findall(r'```python\n(.*?)```', section, flags=re.S)
    assert block.startswith('# configs/<your rig>/')
    base = osp.join(ROOT, 'configs', 'sdg_occ') + '/'
    filled = block.replace("'../sdg_occ/", repr(base)[:-1])
    assert filled != block, 'the example changed its base path'
    (tmp_path / 'my_rig.py').write_text(filled)
    cfg = Config.fromfile(str(tmp_path / 'my_rig.py'))
    paper = Config.fromfile(
        osp.join(base, 'sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py'))
    for split in ('train', 'val', 'test'):
        dataset = cfg[f'{split}_dataloader'].dataset
        assert dataset.cam_names == [
            'CAM_FRONT', 'CAM_LEFT', 'CAM_BACK', 'CAM_RIGHT']
        assert dataset.data_root == 'data/my_rig/'
        assert dataset.pipeline == paper[
            f'{split}_dataloader'].dataset.pipeline
    assert cfg.model == paper.model
