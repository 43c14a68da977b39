"""Tests of the composed occupancy losses and the majority-vote GT
down-sampling of the multi-scale one."""
import math

import pytest
import torch

from projects.occ_common.models.losses import (MultiScaleOccupancyLoss,
                                               OccFocalLoss, OccLovaszLoss,
                                               OccupancyLoss,
                                               SceneClassAffinityLoss,
                                               downsample_occupancy_gt,
                                               term_name)

E, IGN = 0, 255  # empty, ignore


def _grid_from_blocks(blocks, size=4, factor=2):
    """Fill a (size,)*3 grid block by block; ``blocks[(i, j, k)]`` lists
    the factor^3 labels of that block in (x, y, z) row-major order."""
    grid = torch.zeros(size, size, size, dtype=torch.long)
    for (i, j, k), labels in blocks.items():
        grid[i * factor:(i + 1) * factor, j * factor:(j + 1) * factor,
             k * factor:(k + 1) * factor] = torch.tensor(labels).reshape(
                 factor, factor, factor)
    return grid


BLOCKS = {
    (0, 0, 0): [E] * 8,                           # all empty -> 0
    (0, 0, 1): [E] * 5 + [2, 2, 1],               # empty 5 votes lose -> 2
    (0, 1, 0): [IGN] * 8,                         # all ignored -> 255
    (0, 1, 1): [IGN] * 6 + [3, E],                # one object voxel -> 3
    (1, 0, 0): [1, 1, 3, 3, E, E, E, E],          # tie 1 vs 3 -> 1
    (1, 0, 1): [E] * 4 + [IGN] * 4,               # empty + ignored -> 0
    (1, 1, 0): [4] * 8,                           # uniform -> 4
    (1, 1, 1): [IGN] * 3 + [3, 3, 3, 1, 1],       # 3 beats 1 -> 3
}
EXPECTED = [[[0, 2], [255, 3]], [[1, 0], [4, 3]]]


def test_downsample_majority_vote():
    """Each 2^3 block of BLOCKS goes to the label in its comment:
    occupied labels vote, empty wins only when nothing is occupied,
    all-ignored stays 255, ties go to the smaller class index."""
    grid = _grid_from_blocks(BLOCKS)
    before = grid.clone()
    out = downsample_occupancy_gt(grid[None], 2)
    assert out.tolist() == [EXPECTED]
    assert out.dtype == grid.dtype
    assert torch.equal(grid, before)
    assert downsample_occupancy_gt(grid, 2).tolist() == EXPECTED


def test_downsample_occ3d_free_last():
    """empty_index = 17: 'others' (0) is an occupied class and wins over
    7 free voxels; an all-free block stays 17; factor 4 merges all."""
    grid = torch.full((4, 4, 4), 17)
    grid[0, 0, 0] = 0
    out = downsample_occupancy_gt(grid, 2, empty_index=17)
    expected = torch.full((2, 2, 2), 17)
    expected[0, 0, 0] = 0
    assert torch.equal(out, expected)
    assert downsample_occupancy_gt(grid, 4, empty_index=17).tolist() == \
        [[[0]]]


def test_downsample_edge_cases():
    """factor 1 copies; an all-ignored grid stays ignored; errors."""
    grid = _grid_from_blocks(BLOCKS)
    copy = downsample_occupancy_gt(grid, 1)
    assert torch.equal(copy, grid) and copy is not grid
    ignored = torch.full((1, 2, 2, 2), 255)
    assert downsample_occupancy_gt(ignored, 2).tolist() == [[[[255]]]]
    with pytest.raises(ValueError, match='multiple of factor=3'):
        downsample_occupancy_gt(grid, 3)
    with pytest.raises(ValueError, match='integer labels'):
        downsample_occupancy_gt(grid.float(), 2)
    with pytest.raises(ValueError, match='negative'):
        downsample_occupancy_gt(grid - 1, 2)


@pytest.mark.parametrize('gpu', [False, True])
def test_downsample_with_known_classes_is_the_same_vote(gpu):
    """Given the class count (what the multi-scale loss passes), the GPUs'
    path votes without host reads and gives the same labels as the vote
    that reads the largest label, all-ignored blocks included (255)."""
    from projects.occ_common.utils.device_path import forced_accelerator_path
    gen = torch.Generator().manual_seed(5)
    grid = torch.randint(0, 6, (2, 8, 8, 4), generator=gen)
    grid[torch.rand(grid.shape, generator=gen) < 0.3] = 255
    grid[0, :2, :2, :2] = 255
    expected = downsample_occupancy_gt(grid, 2, empty_index=5)
    assert expected[0, 0, 0, 0] == 255
    with forced_accelerator_path(gpu):
        out = downsample_occupancy_gt(grid, 2, empty_index=5, num_classes=6)
    assert torch.equal(out, expected)


def test_multi_scale_hand_computed(code_path):
    """Logits all 0 over C = 5 classes: p = 1/5 everywhere, so the focal
    term of every supervised voxel is (4/5)^2 ln 5 = 0.64 * 1.6094379
    = 1.0300403, whatever the label. Scale 0 (4^3 GT) averages it: 1.0300403;
    scale 1 (the 2^3 voted GT, 7 supervised blocks) also averages to it
    and is weighted 1/2: 0.5150201.
    """
    gt = _grid_from_blocks(BLOCKS)[None]
    logits = [
        torch.zeros(1, 5, 4, 4, 4, requires_grad=True),
        torch.zeros(1, 5, 2, 2, 2, requires_grad=True)
    ]
    loss = MultiScaleOccupancyLoss(
        losses=[dict(type='OccFocalLoss'),
                dict(type='SceneClassAffinityLoss', mode='geo')],
        num_scales=2)
    terms = loss(logits, gt)
    assert sorted(terms) == [
        'loss_focal_s0', 'loss_focal_s1', 'loss_geo_scal_s0',
        'loss_geo_scal_s1'
    ]
    per_voxel = 0.64 * math.log(5)
    assert terms['loss_focal_s0'].item() == pytest.approx(per_voxel, 1e-6)
    assert terms['loss_focal_s1'].item() == pytest.approx(
        per_voxel / 2, 1e-6)
    coarse = torch.tensor([EXPECTED])
    assert terms['loss_geo_scal_s1'].item() == pytest.approx(
        SceneClassAffinityLoss()(logits[1], coarse).item() / 2, 1e-6)
    sum(terms.values()).backward()
    assert all(torch.isfinite(x.grad).all() for x in logits)


def test_multi_scale_all_ignored_is_finite(code_path):
    """An all-ignored GT gives zero terms and zero gradients."""
    gt = torch.full((1, 4, 4, 2), 255)
    logits = [
        torch.randn(1, 3, 4, 4, 2, requires_grad=True),
        torch.randn(1, 3, 2, 2, 1, requires_grad=True)
    ]
    loss = MultiScaleOccupancyLoss([OccFocalLoss()], num_scales=2)
    terms = loss(logits, gt)
    assert [t.item() for t in terms.values()] == [0.0, 0.0]
    sum(terms.values()).backward()
    assert all(torch.equal(x.grad, torch.zeros_like(x)) for x in logits)


def test_multi_scale_bad_inputs_raise():
    """Wrong scale count or grid, clashing names or labels."""
    gt = torch.zeros(1, 4, 4, 2, dtype=torch.long)
    loss = MultiScaleOccupancyLoss([OccFocalLoss()], num_scales=2)
    with pytest.raises(ValueError, match='expected 2 predictions'):
        loss([torch.zeros(1, 3, 4, 4, 2)], gt)
    with pytest.raises(ValueError, match='scale 1 predicts'):
        loss([torch.zeros(1, 3, 4, 4, 2), torch.zeros(1, 3, 4, 4, 2)], gt)
    with pytest.raises(ValueError, match='share a name'):
        MultiScaleOccupancyLoss([OccFocalLoss(), OccFocalLoss()])
    with pytest.raises(ValueError, match='empty_index=17'):
        MultiScaleOccupancyLoss([SceneClassAffinityLoss(empty_index=17)])


def test_labels_are_stated_once_on_the_composed_loss():
    """Occ3D's empty 17 and ignore 200 reach every term config that takes
    them (SCAL takes both, focal only the ignore label); a term module
    built elsewhere with other labels is refused."""
    loss = OccupancyLoss([
        dict(type='OccFocalLoss'),
        dict(type='SceneClassAffinityLoss', mode='sem')
    ], empty_index=17, ignore_index=200)
    focal, scal = loss.losses
    assert focal.ignore_index == 200 and not hasattr(focal, 'empty_index')
    assert (scal.empty_index, scal.ignore_index) == (17, 200)
    with pytest.raises(ValueError, match='ignore_index=255'):
        OccupancyLoss([OccFocalLoss()], ignore_index=200)


def test_single_scale_terms_and_suffix():
    """One key per term, the suffix appended, each the term's own value."""
    gen = torch.Generator().manual_seed(0)
    logits = torch.randn(2, 3, 4, 4, 2, generator=gen)
    gt = torch.randint(0, 3, (2, 4, 4, 2), generator=gen)
    loss = OccupancyLoss([dict(type='OccFocalLoss', gamma=0.0),
                          dict(type='OccLovaszLoss')])
    terms = loss(logits, gt, suffix='_teacher')
    assert list(terms) == ['loss_focal_teacher', 'loss_lovasz_teacher']
    ref = torch.nn.functional.cross_entropy(logits, gt)
    assert terms['loss_focal_teacher'].item() == pytest.approx(ref.item())


def test_term_name():
    """loss_name wins; otherwise the snake-cased class without 'Loss'."""

    class MyThingLoss(torch.nn.Module):
        pass

    assert term_name(OccFocalLoss()) == 'loss_focal'
    assert term_name(SceneClassAffinityLoss(mode='geo')) == 'loss_geo_scal'
    assert term_name(MyThingLoss()) == 'loss_my_thing'


def test_terms_share_one_selection_and_softmax(monkeypatch, code_path):
    """The composed loss selects the supervised voxels and takes their
    softmax once per scale for all its terms (the terms used to do both
    each: 4 softmaxes a scale), and every term's value and the gradient of
    the sum equal those of the terms called one by one.

    Two scales of a (2, 5, 4, 4, 4) prediction, 5 classes, a few ignored
    voxels, the four terms of OccCylindrical's config."""
    import torch.nn.functional as F
    gen = torch.Generator().manual_seed(4)
    scales = [
        torch.randn(2, 5, 4, 4, 4, generator=gen, requires_grad=True),
        torch.randn(2, 5, 2, 2, 2, generator=gen, requires_grad=True)
    ]
    gt = torch.randint(0, 5, (2, 4, 4, 4), generator=gen)
    gt[0, 0, 0] = IGN
    terms = [dict(type='OccFocalLoss'), dict(type='OccLovaszLoss'),
             dict(type='SceneClassAffinityLoss', mode='geo'),
             dict(type='SceneClassAffinityLoss', mode='sem')]
    loss = MultiScaleOccupancyLoss(terms, num_scales=2)
    calls = []
    for name in ('softmax', 'log_softmax'):
        real = getattr(F, name)
        monkeypatch.setattr(
            F, name,
            lambda *a, _real=real, _name=name, **k: calls.append(_name) or
            _real(*a, **k))
    composed = loss(scales, gt)
    monkeypatch.undo()
    assert calls == ['log_softmax', 'log_softmax']
    (grad0, grad1) = torch.autograd.grad(sum(composed.values()), scales)

    alone = {}
    for level, logits in enumerate(scales):
        target = downsample_occupancy_gt(gt, 2**level, E, IGN)
        for term in loss.losses:
            alone[f'{term_name(term)}_s{level}'] = term(logits,
                                                        target) / 2**level
    assert list(alone) == list(composed)
    for key, value in alone.items():
        torch.testing.assert_close(composed[key], value)
    (ref0, ref1) = torch.autograd.grad(sum(alone.values()), scales)
    torch.testing.assert_close(grad0, ref0)
    torch.testing.assert_close(grad1, ref1)


@pytest.mark.parametrize('ignored', [0.3, 1.0])
def test_gpu_path_masks_what_the_cpu_path_selects(ignored):
    """The GPU path (and compiled code) keeps every voxel and masks the
    ignored ones out of each term instead of selecting the supervised ones
    (a host read of their number): the four terms of OccCylindrical's
    config, Lovasz over the present and over all classes, give the CPU
    path's values and gradients with 30 % of the voxels ignored, and the
    same zeros with all of them ignored."""
    from projects.occ_common.utils.device_path import forced_accelerator_path
    gen = torch.Generator().manual_seed(7)
    logits = torch.randn(2, 5, 4, 4, 2, generator=gen)
    gt = torch.randint(0, 4, (2, 4, 4, 2), generator=gen)  # class 4 absent
    gt[torch.rand(gt.shape, generator=gen) < ignored] = IGN
    every_class = OccLovaszLoss(classes='all', loss_weight=0.5)
    every_class.loss_name = 'loss_lovasz_all'
    loss = OccupancyLoss([
        dict(type='OccFocalLoss'),
        dict(type='OccLovaszLoss'), every_class,
        dict(type='SceneClassAffinityLoss', mode='geo'),
        dict(type='SceneClassAffinityLoss', mode='sem')
    ])
    results = []
    for gpu in (False, True):
        with forced_accelerator_path(gpu):
            x = logits.clone().requires_grad_()
            terms = loss(x, gt)
            grad, = torch.autograd.grad(sum(terms.values()), x)
        results.append((terms, grad))
    (cpu, cpu_grad), (gpu, gpu_grad) = results
    assert list(cpu) == list(gpu)
    for key in cpu:
        torch.testing.assert_close(gpu[key], cpu[key], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(gpu_grad, cpu_grad, rtol=1e-5, atol=1e-6)
    if ignored == 1.0:
        assert all(float(v.detach()) == 0 for v in gpu.values())
        assert not gpu_grad.any()
