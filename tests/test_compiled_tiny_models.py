"""The tiny models compiled by inductor on the CPU give eager's logits.

Compiled code takes the GPU's code path (masks instead of selections,
padded voxel lists, eager islands for the LiDAR steps); inductor fuses
and reorders float32 arithmetic, so the logits agree to a tolerance, not
bitwise: atol 1e-4 + rtol 1e-4 on logits of magnitude ~1-10 (float32
round-off through ~50 layers), and the predicted labels agree on at
least 99.9 % of the voxels (a tie of two logits within 1e-4 may flip).
A second point count must reuse the compiled graphs' code (it is marked
dynamic), so it is checked too. Needs a C++ compiler (inductor's CPU
backend); slow (inductor compiles for a minute or more per model).
"""
import shutil

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

from projects.occ_common.testing.tool_logs import load_tool

CONFIGS = [
    'configs/sdg_occ/sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py',
]


def _logits(out):
    return out[0] if isinstance(out, (tuple, list)) else out


@pytest.mark.slow
@pytest.mark.skipif(shutil.which('g++') is None and shutil.which('c++') is
                    None, reason="inductor's CPU backend needs a C++ "
                    'compiler')
@pytest.mark.parametrize('config', CONFIGS)
def test_inductor_equals_eager(config):
    preprocessed = load_tool(
        'tools/analysis_tools/graph_breaks.py').preprocessed
    cfg = Config.fromfile(config)
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    model = MODELS.build(cfg.model).eval()

    def forward(data):
        with torch.no_grad():
            return _logits(model(data['inputs'], data['data_samples'],
                                 mode='tensor'))

    torch._dynamo.reset()
    compiled = torch.compile(forward)
    try:
        for points, seed in ((600, 0), (450, 1)):
            eager = forward(preprocessed(model, cfg, 1, points, False,
                                         seed=seed))
            fast = compiled(preprocessed(model, cfg, 1, points, False,
                                         seed=seed))
            assert fast.shape == eager.shape and eager.abs().max() > 0.1
            torch.testing.assert_close(fast, eager, atol=1e-4, rtol=1e-4)
            same = (fast.argmax(1) == eager.argmax(1)).float().mean()
            assert same >= 0.999
    finally:
        torch._dynamo.reset()
