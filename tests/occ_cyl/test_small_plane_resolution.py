"""The small config's finest TPV-polar level keeps one cell per cylinder
column (issue 14).

The head samples the finest level of each plane at the 200 x 200 x 16
output voxels (0.5 m). With the base's patch stride 2 the small cylinder's
finest (R, Theta) level had half its resolution in both directions.
"""
import os.path as osp

import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SMALL = osp.join(ROOT, 'configs', 'occ_cyl',
                 'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py')


def test_finest_level_has_the_cylinders_resolution():
    """Cylinder 64 x 128 x 16 over 50 m and 360 degrees: (R, Theta) cells
    of 50 / 64 = 0.78 m x 360 / 128 = 2.8 degrees. With patch stride 1 the
    four levels have strides 1, 2, 4, 8 and the finest planes are 64 x 128,
    128 x 16 and 64 x 16; with the base's stride 2 they were 32 x 64, 64 x 8
    and 32 x 8 (1.56 m x 5.6 degrees: 3.9 m of arc at 40 m, about 8
    output voxels)."""
    cfg = Config.fromfile(SMALL)
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    encoder = MODELS.build(cfg.model.tpv_encoder).eval()
    r, t, z = cfg.model.cylinder.shape
    assert (r, t, z) == (64, 128, 16)
    assert encoder.level_strides == (1, 2, 4, 8)
    c = cfg.model.tpv_fusion.plane_channels
    planes = [torch.randn(1, c, *hw) for hw in ((r, t), (t, z), (r, z))]
    with torch.no_grad():
        finest = encoder(planes)[0]
    assert [tuple(p.shape) for p in finest] == [(1, c, 64, 128),
                                                (1, c, 128, 16),
                                                (1, c, 64, 16)]
