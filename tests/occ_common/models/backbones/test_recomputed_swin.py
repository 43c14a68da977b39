"""RecomputedSwinTransformer: mmdet's Swin, recomputed non-reentrantly."""
import warnings

import torch
from mmdet.models.backbones import SwinTransformer

from projects.occ_common.models.backbones import RecomputedSwinTransformer
from projects.occ_common.testing.autograd_memory import same_weights_pair


def _step(model, x):
    """One forward and backward under a fixed random state (drop path is
    on); the outputs, the input's and every parameter's gradient."""
    torch.manual_seed(1)
    model.zero_grad()
    x = x.clone().requires_grad_()
    outs = model(x)
    sum((out * out.flip(-1)).sum() * (i + 1)
        for i, out in enumerate(outs)).backward()
    return [o.detach() for o in outs] + [x.grad] + [
        p.grad for p in model.parameters()
    ]


def test_same_as_mmdet_without_recomputation_and_no_warning():
    """A 2-stage Swin (8 channels in, embed 8, depths (2, 2), window 2,
    drop path 0.3, float64, training) on a 1 x 8 x 16 x 16 input: the
    outputs, the input's gradient and every parameter's gradient equal
    mmdet's without recomputation to 1e-12 (the drop-path masks are
    redrawn from the saved random state); the weights load by mmdet's
    names; every block runs twice (forward and recomputation); and no
    ``use_reentrant`` warning is raised, where mmdet's own ``with_cp``
    warns."""
    kwargs = dict(in_channels=8, embed_dims=8, depths=(2, 2),
                  num_heads=(1, 2), window_size=2, patch_size=2,
                  strides=(2, 2), out_indices=(0, 1), drop_path_rate=0.3,
                  init_cfg=None)
    reference, recomputed = same_weights_pair(SwinTransformer,
                                              RecomputedSwinTransformer,
                                              **kwargs)
    calls = []
    for stage in recomputed.stages:
        for block in stage.blocks:
            block.register_forward_pre_hook(lambda *a: calls.append(1))
    x = torch.randn(1, 8, 16, 16, dtype=torch.float64)
    expected = _step(reference, x)
    with warnings.catch_warnings():
        warnings.filterwarnings('error', message='.*use_reentrant.*')
        got = _step(recomputed, x)
    assert [o.shape for o in got[:2]] == [(1, 8, 8, 8), (1, 16, 4, 4)]
    for a, b in zip(expected, got):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    assert len(calls) == 2 * 4
    mmdet_cp = SwinTransformer(with_cp=True, **kwargs).double()
    mmdet_cp.train()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        _step(mmdet_cp, x)
    assert any('use_reentrant' in str(w.message) for w in caught)
