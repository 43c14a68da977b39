"""The export forms of SDG's scatter and window operations.

``bev_pool`` and the semantic diffusion take another form while a graph
is being exported (``scatter_add`` for ``index_add``, shifted slices for
``unfold``); exported and run by onnxruntime, they must give what the
eager GPU path gives, also on inputs other than the traced ones.
"""
import torch
from torch import nn

from projects.occ_common.deployment import (export_graph, graph_summary,
                                            onnx_session, run_graph)
from projects.occ_common.utils.device_path import forced_accelerator_path
from projects.sdg_occ import (bev_pool, bev_pool_indices,
                              semantic_depth_diffusion)

# A 2 x 2 BEV over x, y in [0, 2), z in [0, 1): 1 m cells.
PC_RANGE = (0.0, 0.0, 0.0, 2.0, 2.0, 1.0)


class _Pool(nn.Module):

    def forward(self, coords, feats, weights):
        index = bev_pool_indices(coords, torch.zeros_like(weights).long(),
                                 torch.arange(coords.shape[0]), 1, PC_RANGE,
                                 (2, 2))
        return bev_pool(feats, weights, index)


def test_bev_pool_sums_repeated_cells(tmp_path):
    """Four points, three in cell (y=0, x=1), one outside (z = 1.5).

    Traced with those; run on new weights 1, 2, 3, 4 and features
    (1, 10), (2, 20), (3, 30), (4, 40): cell (0, 1) = 1*(1, 10) +
    2*(2, 20) + 3*(3, 30) = (14, 140); index_add's ONNX form would keep
    one of the three instead of their sum.
    """
    coords = torch.tensor([[1.5, 0.5, 0.5], [1.2, 0.1, 0.2],
                           [1.9, 0.9, 0.9], [0.5, 0.5, 1.5]])
    feats = torch.tensor([[1., 10.], [2., 20.], [3., 30.], [4., 40.]])
    path = export_graph(_Pool(), [coords, feats, torch.ones(4)],
                        str(tmp_path / 'pool.onnx'),
                        ['coords', 'feats', 'weights'], ['bev'],
                        {k: {0: 'points'} for k in ('coords', 'feats',
                                                    'weights')})
    assert graph_summary(path)['ops'].get('ScatterElements') == 1
    weights = torch.tensor([1., 2., 3., 4.])
    got = run_graph(onnx_session(path),
                    dict(coords=coords, feats=feats, weights=weights))['bev']
    expected = torch.zeros(1, 2, 2, 2)
    expected[0, :, 0, 1] = torch.tensor([14., 140.])
    torch.testing.assert_close(torch.from_numpy(got), expected)
    with forced_accelerator_path(True):
        torch.testing.assert_close(_Pool()(coords, feats, weights), expected)


class _Diffuse(nn.Module):

    def forward(self, depth, seg):
        return semantic_depth_diffusion(depth, seg, 2.0)


def test_diffusion_windows_match_the_eager_gpu_path(tmp_path):
    """Random sparse maps of two classes: the exported slices give the
    eager unfold's result, on maps other than the traced ones."""
    gen = torch.Generator().manual_seed(0)

    def maps():
        depth = torch.rand(2, 6, 9, generator=gen) * 40
        depth[torch.rand(2, 6, 9, generator=gen) < 0.7] = 0
        return depth, torch.randint(0, 3, (2, 6, 9), generator=gen)

    path = export_graph(_Diffuse(), list(maps()), str(tmp_path / 'd.onnx'),
                        ['depth', 'seg'], ['ext'])
    depth, seg = maps()
    got = run_graph(onnx_session(path), dict(depth=depth, seg=seg))['ext']
    with forced_accelerator_path(True):
        torch.testing.assert_close(
            torch.from_numpy(got), semantic_depth_diffusion(depth, seg, 2.0))


def test_neighborhood_fusion_is_a_compact_graph(tmp_path):
    """SDG-Fusion's attention (k = 7, 4 heads) on a 20 x 24 map: the GPU
    path (border windows gathered at once, the interior in k^2 strided
    views) is a few hundred operations, not the CPU path's row blocks
    (22,189 nodes at paper size before); onnxruntime agrees with PyTorch
    on maps other than the traced ones."""
    from projects.sdg_occ import NeighborhoodFusion
    torch.manual_seed(0)
    fusion = NeighborhoodFusion(8, 12, 8, embed_dims=16, num_heads=4,
                                kernel_size=7).eval()
    path = export_graph(fusion, [torch.randn(1, 8, 20, 24),
                                 torch.randn(1, 12, 20, 24)],
                        str(tmp_path / 'fusion.onnx'), ['source', 'cross'],
                        ['fused'])
    assert graph_summary(path)['nodes'] < 700
    source, cross = torch.randn(1, 8, 20, 24), torch.randn(1, 12, 20, 24)
    got = run_graph(onnx_session(path), dict(source=source,
                                             cross=cross))['fused']
    with torch.no_grad():
        torch.testing.assert_close(
            torch.from_numpy(got), fusion(source, cross), atol=1e-5,
            rtol=1e-5)


def test_export_leaves_the_model_in_eval_mode(tmp_path):
    """The exporter restores the exported module's mode: a wrapper built
    in training mode would put the model it holds back into training (its
    BatchNorms then normalise with batch statistics, and PyTorch's
    reference differs from the graph). export_graph evaluates it first."""
    model = nn.Sequential(nn.Conv2d(2, 2, 1), nn.BatchNorm2d(2)).eval()
    wrapper = nn.Sequential(model)  # training mode, as nn.Module starts
    export_graph(wrapper, [torch.randn(1, 2, 3, 3)],
                 str(tmp_path / 'bn.onnx'), ['x'], ['y'])
    assert not model.training and not model[1].training
