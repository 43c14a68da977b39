"""Tests of SPVCNNEncoder on an 8x8x4 grid of 1 m voxels.

The tiny configuration: range (0, 0, 0, 8, 8, 4), stem 4 channels, stages
(8, 8) with strides (2, 1) -> last stage 4x4x2 voxels of 2 m, BEV 4x4 cells
of 2 m, 6 output channels.
"""
import copy

import pytest
import torch
from torch import nn

from projects.occ_common.models.sparse import SPVCNNEncoder
from projects.occ_common.testing.sparse_reference import \
    reference_spvcnn_forward


def _spconv_runs_on_cpu():
    """Whether a tiny spconv submanifold conv runs on CPU."""
    try:
        import spconv.pytorch as spconv
        x = spconv.SparseConvTensor(
            torch.ones(1, 1), torch.zeros(1, 4, dtype=torch.int32),
            [1, 1, 1], 1)
        spconv.SubMConv3d(1, 1, 3)(x)
    except Exception:  # missing or unusable spconv
        return False
    return True


def _encoder(**kwargs):
    cfg = dict(
        in_channels=4,
        voxel_size=(1.0, 1.0, 1.0),
        point_cloud_range=(0.0, 0.0, 0.0, 8.0, 8.0, 4.0),
        base_channels=4,
        stage_channels=(8, 8),
        stage_strides=(2, 1),
        bev_shape=(4, 4),
        out_channels=6,
        backend='torch')
    cfg.update(kwargs)
    torch.manual_seed(0)
    return SPVCNNEncoder(**cfg)


def _cloud(num, seed, columns=4):
    """``num`` points uniformly inside the range, intensity in [0, 1)."""
    gen = torch.Generator().manual_seed(seed)
    scale = torch.tensor([8.0, 8.0, 4.0] + [1.0] * (columns - 3))
    return torch.rand(num, columns, generator=gen) * scale


def test_forward_backward_shapes_and_gradients():
    """Two samples (30 and 20 points, plus 3 outside the range): BEV
    (2, 6, 4, 4) >= 0 (ReLU then max), bool mask (2, 1, 4, 4), and every
    parameter receives a finite gradient."""
    enc = _encoder()
    outside = torch.tensor([[9., 1., 1., 0.], [1., 1., -0.5, 0.],
                            [1., 8., 1., 0.]])
    out = enc([torch.cat([_cloud(30, 0), outside]), _cloud(20, 1)])
    bev, mask = out['bev'], out['bev_mask']
    assert bev.shape == (2, 6, 4, 4) and mask.shape == (2, 1, 4, 4)
    assert mask.dtype == torch.bool
    assert bool(torch.isfinite(bev).all()) and bool((bev >= 0).all())
    (bev * torch.randn_like(bev)).sum().backward()
    for name, param in enc.named_parameters():
        assert param.grad is not None, name
        assert bool(torch.isfinite(param.grad).all()), name


def test_bev_mask_by_hand(code_path):
    """Cell = floor(voxel centre / 2 m) per axis, (row y, column x):
    sample 0: (0.5, 0.5, 0.5) -> voxel (0, 0) -> cell (0, 0);
    (1.2, 0.3, 3.5) -> voxel (1, 0) -> centre (1.5, 0.5) -> cell (0, 0);
    (5.5, 2.5, 1.0) -> centre (5.5, 2.5) -> cell (y1, x2);
    (7.9, 7.9, 3.9) -> cell (3, 3); (9, 1, 1) and (1, 1, 4.0) lie outside
    (x >= 8, z >= 4) and are dropped.
    sample 1: (3.0, 6.0, 0.0) -> centre (3.5, 6.5) -> cell (y3, x1).
    Features may be non-zero only where the mask is True."""
    enc = _encoder()
    sample0 = torch.tensor([[0.5, 0.5, 0.5, 0.1], [1.2, 0.3, 3.5, 0.2],
                            [5.5, 2.5, 1.0, 0.3], [7.9, 7.9, 3.9, 0.4],
                            [9.0, 1.0, 1.0, 0.5], [1.0, 1.0, 4.0, 0.6]])
    sample1 = torch.tensor([[3.0, 6.0, 0.0, 0.7]])
    out = enc([sample0, sample1])
    expected = torch.zeros(2, 1, 4, 4, dtype=torch.bool)
    for b, y, x in ((0, 0, 0), (0, 1, 2), (0, 3, 3), (1, 3, 1)):
        expected[b, 0, y, x] = True
    assert torch.equal(out['bev_mask'], expected)
    active = out['bev'].abs().sum(dim=1, keepdim=True) > 0
    assert not bool((active & ~expected).any())


def test_point_offsets_are_the_point_inputs():
    """point_offsets=True: each point enters the point MLP as its 4 values
    then its offsets to the voxel mean and centre (1 m voxels from 0).

    (0.2, 0.4, 0.6, i=1) and (0.6, 0.8, 0.2, i=3) share voxel (0, 0, 0),
    centre (0.5, 0.5, 0.5), mean (0.4, 0.6, 0.4): offsets to the mean
    (-0.2, -0.2, 0.2) and (0.2, 0.2, -0.2), to the centre (-0.3, -0.1,
    0.1) and (0.1, 0.3, -0.3). (3.5, 2.5, 1.5, i=2) is alone at its
    voxel's centre: all six offsets 0. The stem then gets the mean of the
    MLP outputs per voxel (without the option, the mean of the raw 4
    values)."""
    enc = _encoder(point_offsets=True).eval()
    cloud = torch.tensor([[0.2, 0.4, 0.6, 1.0], [0.6, 0.8, 0.2, 3.0],
                          [3.5, 2.5, 1.5, 2.0]])
    seen = {}
    enc.point_input.register_forward_hook(
        lambda mod, args, out: seen.update(points=args[0], mlp=out))
    enc.stem[0].register_forward_pre_hook(
        lambda mod, args: seen.update(stem=args[0].features))
    enc([cloud])
    rows = sorted(seen['points'].tolist())
    expected = sorted([[0.2, 0.4, 0.6, 1.0, -0.2, -0.2, 0.2, -0.3, -0.1, 0.1],
                       [0.6, 0.8, 0.2, 3.0, 0.2, 0.2, -0.2, 0.1, 0.3, -0.3],
                       [3.5, 2.5, 1.5, 2.0, 0, 0, 0, 0, 0, 0]])
    torch.testing.assert_close(torch.tensor(rows), torch.tensor(expected))
    # Rows are grouped by voxel: the two points of voxel 0 come first.
    mlp = seen['mlp']
    torch.testing.assert_close(seen['stem'],
                               torch.stack([mlp[:2].mean(0), mlp[2]]))
    plain = _encoder().eval()
    plain.stem[0].register_forward_pre_hook(
        lambda mod, args: seen.update(plain=args[0].features))
    plain([cloud])
    torch.testing.assert_close(
        seen['plain'], torch.stack([cloud[:2].mean(0), cloud[2]]))
    out = _encoder(point_offsets=True)([torch.zeros(0, 4)])
    assert out['bev'].abs().sum().item() == 0.


def test_empty_point_cloud(code_path):
    """No points at all: zero BEV, all-False mask, and backward still
    reaches every parameter (with zero gradient)."""
    enc = _encoder()
    out = enc([torch.zeros(0, 4), torch.zeros(0, 5)])
    assert out['bev'].shape == (2, 6, 4, 4)
    assert out['bev'].abs().sum().item() == 0.
    assert not bool(out['bev_mask'].any())
    out['bev'].sum().backward()
    conv_weight = enc.stem[0].conv.weight
    assert conv_weight.grad is not None
    assert torch.count_nonzero(conv_weight.grad) == 0


def test_batch_with_one_empty_sample(code_path):
    """A batch [cloud, empty] equals [cloud] alone for sample 0 (eval mode,
    and in training the empty sample adds no rows to the batch norms);
    sample 1 is zero with an all-False mask. Backward runs in training."""
    enc = _encoder().eval()
    cloud = _cloud(25, 2)
    both = enc([cloud, torch.zeros(0, 4)])
    alone = enc([cloud])
    torch.testing.assert_close(both['bev'][0], alone['bev'][0])
    assert torch.equal(both['bev_mask'][0], alone['bev_mask'][0])
    assert both['bev'][1].abs().sum().item() == 0.
    assert not bool(both['bev_mask'][1].any())
    enc.train()
    first_empty = enc([torch.zeros(0, 4), cloud])
    first_empty['bev'].sum().backward()
    assert first_empty['bev'][0].abs().sum().item() == 0.
    assert enc.bev_proj.linear.weight.grad.abs().sum().item() > 0


def test_sync_batchnorm_conversion():
    """convert_sync_batchnorm (the runner's sync_bn) swaps every norm for a
    SyncBatchNorm; without a process group it computes plain batch norm,
    so the converted copy gives the same training-mode BEV, also for a
    batch whose only sample is empty."""
    enc = _encoder()
    synced = nn.SyncBatchNorm.convert_sync_batchnorm(copy.deepcopy(enc))
    assert isinstance(synced.stem[0].norm, nn.SyncBatchNorm)
    assert isinstance(synced.point_mlps[0].norm, nn.SyncBatchNorm)
    cloud = [_cloud(30, 8)]
    torch.testing.assert_close(synced(cloud)['bev'], enc(cloud)['bev'])
    empty = synced([torch.zeros(0, 4)])
    assert empty['bev'].abs().sum().item() == 0.


def test_point_order_does_not_matter():
    """Shuffling the points of a sample leaves the BEV unchanged (eval)."""
    enc = _encoder().eval()
    cloud = _cloud(40, 3)
    shuffled = cloud[torch.randperm(40, generator=torch.Generator()
                                    .manual_seed(5))]
    torch.testing.assert_close(enc([cloud])['bev'], enc([shuffled])['bev'])


def test_concat_reduction_and_five_columns():
    """bev_reduce='concat' stacks the 2 height levels of 8 channels (16)
    and mixes them to 6; five input columns with in_channels=5 work."""
    enc = _encoder(bev_reduce='concat', in_channels=5)
    assert enc.bev_proj[0].in_channels == 16
    out = enc([_cloud(20, 4, columns=5)])
    assert out['bev'].shape == (1, 6, 4, 4)
    out['bev'].sum().backward()
    assert enc.bev_proj[0].weight.grad is not None


def test_concat_reduction_is_zero_off_the_mask():
    """With 'concat' the BEV passes a dense 1x1 conv + BN + ReLU, whose
    shift (here beta = 0.5, eval mode with running mean 0 and var 1) would
    give every cell 0.5 / sqrt(1 + 1e-5) > 0. One point at (0.5, 0.5, 0.5)
    fills only cell (0, 0): the other 15 cells must stay exactly 0, as
    documented and as with 'max' / 'mean'."""
    enc = _encoder(bev_reduce='concat').eval()
    with torch.no_grad():
        enc.bev_proj[1].bias.fill_(0.5)
    out = enc([torch.tensor([[0.5, 0.5, 0.5, 0.1]])])
    expected = torch.zeros(1, 1, 4, 4, dtype=torch.bool)
    expected[0, 0, 0, 0] = True
    assert torch.equal(out['bev_mask'], expected)
    assert out['bev'][~expected.expand_as(out['bev'])].abs().sum() == 0
    assert bool((out['bev'][0, :, 0, 0] > 0).any())


def test_config_errors():
    """Inconsistent configurations raise ValueError naming the problem."""
    with pytest.raises(ValueError, match='coarser than the BEV cells'):
        _encoder(stage_strides=(2, 2))
    with pytest.raises(ValueError, match="'concat' needs the last stage"):
        _encoder(bev_reduce='concat', bev_shape=(8, 8))
    with pytest.raises(ValueError, match='in_channels must be >= 3'):
        _encoder(in_channels=2)
    with pytest.raises(ValueError, match='one stride >= 1 per stage'):
        _encoder(stage_strides=(2, ))
    with pytest.raises(ValueError, match='blocks_per_stage'):
        _encoder(blocks_per_stage=0)
    with pytest.raises(ValueError, match='bev_reduce must be one of'):
        _encoder(bev_reduce='min')
    with pytest.raises(ValueError, match='point_cloud_range'):
        _encoder(point_cloud_range=(0, 0, 0, 8, 8))
    with pytest.raises(ValueError, match='backend must be one of'):
        _encoder(backend='cuda')


def test_bad_points_input():
    """Points must be a non-empty list of float (N, >= in_channels)
    tensors; errors name the offending sample."""
    enc = _encoder()
    with pytest.raises(ValueError, match='non-empty list or tuple'):
        enc(torch.zeros(5, 4))
    with pytest.raises(ValueError, match='non-empty list or tuple'):
        enc([])
    with pytest.raises(ValueError, match=r'sample 1: .*\(N, >= 4\)'):
        enc([_cloud(3, 0), torch.zeros(5, 3)])
    with pytest.raises(ValueError, match='sample 0'):
        enc([torch.zeros(5, 4, dtype=torch.long)])


def test_default_sdg_occ_geometry_and_registry():
    """Defaults: 0.1 m voxels over 80 x 80 x 6.4 m -> grid (Z, Y, X) =
    (64, 800, 800) (6.4 / 0.1 = 64 despite float error), strides 2 * 2 = 4
    -> 0.4 m, one voxel per 200x200 BEV cell of 80 / 200 = 0.4 m. The
    registry builds the same class."""
    from mmdet3d.registry import MODELS
    enc = MODELS.build(dict(type='SPVCNNEncoder'))
    assert isinstance(enc, SPVCNNEncoder)
    assert enc.sparse_shape == (64, 800, 800)
    assert enc.total_stride == 4
    assert enc.bev_cell == pytest.approx((0.4, 0.4))
    assert enc.bev_shape == (200, 200)


@pytest.mark.skipif(not _spconv_runs_on_cpu(),
                    reason='spconv cannot run on CPU here')
def test_spconv_and_torch_backends_agree():
    """With the same state dict, the spconv backend's forward (CPU) equals
    the torch backend's, in eval mode, including an empty sample."""
    ours = _encoder(backend='torch').eval()
    theirs = _encoder(backend='spconv').eval()
    theirs.load_state_dict(ours.state_dict())
    points = [_cloud(40, 6), torch.zeros(0, 4), _cloud(15, 7)]
    threads = torch.get_num_threads()
    # spconv's CPU strided conv races with several threads (see
    # test_spconv_backend.single_thread).
    torch.set_num_threads(1)
    try:
        out_a, out_b = ours(points), theirs(points)
    finally:
        torch.set_num_threads(threads)
    torch.testing.assert_close(out_a['bev'], out_b['bev'], rtol=1e-5,
                               atol=1e-5)
    assert torch.equal(out_a['bev_mask'], out_b['bev_mask'])


@pytest.mark.parametrize('kwargs', [
    dict(point_offsets=True),
    dict(stage_strides=(2, 2), bev_shape=(2, 2), bev_reduce='mean')
])
def test_forward_and_gradients_match_point_by_point_reference(
        kwargs, code_path):
    """The shared corner lookups, the per-voxel parent lookups, the in-place
    sum and (in eval) the folded point MLPs give the BEV and, in training,
    the parameter gradients of the layers applied point by point
    (``reference_spvcnn_forward``: dense-grid interpolation, a lookup per
    point and stage, unfolded MLPs). 300 points crowd a 3 x 3 x 2 m corner
    (about 17 per voxel, so lookups are shared) and 40 spread out; the
    second sample is smaller."""
    gen = torch.Generator().manual_seed(7)
    crowd = torch.rand(300, 4, generator=gen) * torch.tensor(
        [3.0, 3.0, 2.0, 1.0])
    points = [torch.cat([crowd, _cloud(40, 8)]), _cloud(25, 9)]
    enc = _encoder(**kwargs)
    ref = copy.deepcopy(enc)
    out = enc(points)['bev']
    expected = reference_spvcnn_forward(ref, points)
    torch.testing.assert_close(out, expected)
    weight = torch.randn_like(out)
    (out * weight).sum().backward()
    (expected * weight).sum().backward()
    ref_params = dict(ref.named_parameters())
    for name, param in enc.named_parameters():
        # Gradients reach ~90; atol 1e-4 absorbs the rounding of a bias
        # before a training BatchNorm, whose gradient is 0 (~1e-5 here).
        torch.testing.assert_close(param.grad, ref_params[name].grad,
                                   atol=1e-4, rtol=1e-4, msg=name)
    # Eval, with the running statistics the training pass left.
    enc.eval()
    ref.eval()
    with torch.no_grad():
        torch.testing.assert_close(enc(points)['bev'],
                                   reference_spvcnn_forward(ref, points))


def test_recomputed_encoder_is_exact_and_keeps_only_the_points():
    """``with_cp=True`` (training, float64, two samples of 60 and 45
    points, more than the voxels of any level, with the point offsets'
    MLP): the BEV map, every parameter's
    gradient and every buffer (BatchNorm statistics after the step) equal
    ``with_cp=False``; the stem runs twice (forward and recomputation).
    Of the per-point activations (105 x C, C > 4), the recomputed encoder
    keeps only the input of stage 2 (stage 1's point branch, 105 x 8);
    the plain one keeps at least three."""
    from projects.occ_common.testing.autograd_memory import \
        recorded_training_step
    clouds = [_cloud(60, 1).double(), _cloud(45, 2).double()]
    results = []
    for with_cp in (False, True):
        enc = _encoder(point_offsets=True, with_cp=with_cp).double().train()
        results.append(
            recorded_training_step(enc, enc.stem,
                                   lambda: [enc(clouds)['bev']]))
    (plain, plain_calls, plain_packed), (cp, cp_calls, cp_packed) = results
    for a, b in zip(plain, cp):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    assert (plain_calls, cp_calls) == (1, 2)

    def point_features(shapes):
        return [s for s in shapes if len(s) == 2 and s[0] == 105 and s[1] > 4]

    assert len(point_features(plain_packed)) >= 3
    assert point_features(cp_packed) == [(105, 8)]
