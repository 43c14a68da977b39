"""Tests of OccLovaszLoss on hand-computed voxels."""
import math

import pytest
import torch

from projects.occ_common.models.losses import OccLovaszLoss
from projects.occ_common.models.losses.lovasz_loss import lovasz_softmax_flat

LN3 = math.log(3.0)


def _voxels_5d(labels):
    """Logits (1, 2, 3, 1, 1): p = (0.75, 0.25), (0.5, 0.5), (0.99.., ..).

    The third voxel is meant to be ignored in every test.
    """
    flat = torch.tensor([[LN3, 0.0], [0.0, 0.0], [5.0, -5.0]])
    logits = flat.t().reshape(1, 2, 3, 1, 1).clone().requires_grad_()
    return logits, torch.tensor(labels).reshape(1, 3, 1, 1)


def test_lovasz_hand_computed_present(code_path):
    """Voxel a: label 0, p = (0.75, 0.25); b: label 1, p = (0.5, 0.5).

    class 0: fg = (1, 0), errors |fg - p0| = (0.25, 0.5); sorted (b, a).
      k=1: inter = 1 - 0 = 1, union = 1 + 1 = 2, J = 0.5
      k=2: inter = 1 - 1 = 0, union = 2, J = 1 -> grad (0.5, 0.5)
      loss_0 = 0.5 * 0.5 + 0.25 * 0.5 = 0.375
    class 1: fg = (0, 1), errors (0.25, 0.5); sorted (b, a).
      k=1: inter = 0, union = 1, J = 1; k=2: union = 2, J = 1
      grad (1, 0) -> loss_1 = 0.5
    mean = 0.4375.
    """
    logits, target = _voxels_5d([0, 1, 255])
    loss = OccLovaszLoss()(logits, target)
    assert loss.item() == pytest.approx(0.4375, abs=1e-6)
    loss.backward()
    assert torch.isfinite(logits.grad).all()
    assert torch.equal(logits.grad[0, :, 2], torch.zeros(2, 1, 1))
    assert torch.equal(target[0, 2], torch.tensor([[255]]))


def test_lovasz_class_selection_and_weight(code_path):
    """Same voxels. classes=[1] -> 0.5; class_weight (1, 2) -> (0.375 +
    2 * 0.5) / 2 = 0.6875; loss_weight 2 doubles 0.4375 to 0.875."""
    logits, target = _voxels_5d([0, 1, 255])
    assert OccLovaszLoss(classes=[1])(logits, target).item() == \
        pytest.approx(0.5, abs=1e-6)
    assert OccLovaszLoss(class_weight=[1.0, 2.0])(logits, target).item() \
        == pytest.approx(0.6875, abs=1e-6)
    assert OccLovaszLoss(loss_weight=2.0)(logits, target).item() == \
        pytest.approx(0.875, abs=1e-6)


def test_lovasz_all_includes_absent_class(code_path):
    """Both voxels labelled 0.

    class 0: fg = (1, 1), errors (0.25, 0.5), sorted (0.5, 0.25); gts = 2:
      k=1: inter = 1, union = 2, J = 0.5; k=2: inter = 0, J = 1
      loss_0 = 0.5 * 0.5 + 0.25 * 0.5 = 0.375 ('present' gives this)
    class 1: fg = (0, 0), errors (0.25, 0.5): J = (1, 1), grad (1, 0)
      loss_1 = 0.5 (the largest error); 'all' = (0.375 + 0.5) / 2 = 0.4375.
    """
    logits, target = _voxels_5d([0, 0, 255])
    assert OccLovaszLoss()(logits, target).item() == pytest.approx(
        0.375, abs=1e-6)
    assert OccLovaszLoss(classes='all')(logits, target).item() == \
        pytest.approx(0.4375, abs=1e-6)


def test_lovasz_single_supervised_voxel(code_path):
    """One voxel (label 1, p = (0.5, 0.5)): class 1, error 0.5, J_1 = 1
    -> 0.5. mmdet3d's LovaszLoss loses the class axis in this case."""
    logits, target = _voxels_5d([255, 1, 255])
    loss = OccLovaszLoss()(logits, target)
    assert loss.item() == pytest.approx(0.5, abs=1e-6)
    loss.backward()
    assert torch.isfinite(logits.grad).all()


def test_lovasz_all_ignored_is_finite_zero(code_path):
    """Every voxel ignored: 0 and zero gradients."""
    logits, target = _voxels_5d([255, 255, 255])
    loss = OccLovaszLoss()(logits, target)
    assert loss.item() == 0.0
    loss.backward()
    assert torch.equal(logits.grad, torch.zeros_like(logits))


def test_lovasz_matches_mmdet3d_on_4d_input(code_path):
    """Where mmdet3d's LovaszLoss works (4-D logits, >= 2 supervised
    voxels) it gives the same 0.4375; on 5-D logits it raises, which is
    why this module exists."""
    from mmdet3d.models.losses import LovaszLoss
    logits, target = _voxels_5d([0, 1, 255])
    reference = LovaszLoss(reduction='none')(logits[..., 0], target[..., 0])
    assert reference.item() == pytest.approx(0.4375, abs=1e-6)
    with pytest.raises(ValueError):
        LovaszLoss(reduction='none')(logits, target)


def test_lovasz_bad_inputs_raise():
    """Invalid classes and labels are errors."""
    logits, target = _voxels_5d([0, 1, 7])
    with pytest.raises(ValueError, match='labels'):
        OccLovaszLoss()(logits, target)
    with pytest.raises(ValueError, match='out of range'):
        OccLovaszLoss(classes=[3])(logits, torch.zeros_like(target))
    with pytest.raises(ValueError, match='present'):
        OccLovaszLoss(classes='some')


def test_lovasz_present_sorts_only_present_classes_same_values():
    """Sorting only the present classes changes nothing: with 'present',
    the loss and its gradient equal the mean of the 'all' loss's per-class
    terms over the present classes (classes given as an explicit list),
    on random logits where classes 1 and 4 of 6 never occur."""
    gen = torch.Generator().manual_seed(1)
    logits = torch.randn(1, 6, 6, 5, 2, generator=gen, requires_grad=True)
    labels = torch.tensor([0, 2, 3, 5])[torch.randint(
        0, 4, (1, 6, 5, 2), generator=gen)]
    present = OccLovaszLoss(classes='present')(logits, labels)
    listed = OccLovaszLoss(classes=[0, 2, 3, 5])(logits, labels)
    (g_present, ) = torch.autograd.grad(present, logits)
    (g_listed, ) = torch.autograd.grad(listed, logits)
    torch.testing.assert_close(present, listed)
    torch.testing.assert_close(g_present, g_listed)
    everything = OccLovaszLoss(classes='all')(logits, labels)
    assert not torch.isclose(present, everything)


def _lovasz_by_definition(probs, labels, classes):
    """Berman et al.'s Algorithm 1, one class at a time over every voxel
    (the full sort), as the reference of the pruned sort."""
    terms = []
    for c in classes:
        member = (labels == c).to(probs.dtype)
        errors = (member - probs[:, c]).abs()
        errors_sorted, order = torch.sort(errors, descending=True)
        member_sorted = member[order]
        gts = member.sum()
        jaccard = 1.0 - (gts - member_sorted.cumsum(0)) / (
            gts + (1.0 - member_sorted).cumsum(0))
        jaccard[1:] = jaccard[1:] - jaccard[:-1].clone()
        terms.append((errors_sorted * jaccard).sum())
    return torch.stack(terms).mean()


@pytest.mark.parametrize('classes', ['present', 'all'])
def test_lovasz_sorts_only_the_voxels_that_count(classes, monkeypatch):
    """Voxels whose error is below every member's sort after the last
    member, where g = 0: leaving them out of the sort changes neither the
    loss nor its gradient (float64, 1e-12 against the full-sort definition),
    and each class's sort sees only the voxels with an error >= its
    smallest member error (one voxel for an absent class).

    400 voxels, 85 % of them class 0 ("free"), 5 % each class 1-3, class 4
    absent; logits N(0, 1) plus 3 on the true class."""
    gen = torch.Generator().manual_seed(3)
    labels = torch.multinomial(
        torch.tensor([0.85, 0.05, 0.05, 0.05, 0.0]), 400, replacement=True,
        generator=gen)
    logits = torch.randn(400, 5, generator=gen, dtype=torch.float64)
    logits[torch.arange(400), labels] += 3.0
    logits.requires_grad_()
    sizes = []
    real_sort = torch.sort

    def counting_sort(values, *args, **kwargs):
        sizes.append(values.numel())
        return real_sort(values, *args, **kwargs)

    monkeypatch.setattr(torch, 'sort', counting_sort)
    probs = torch.softmax(logits, dim=1)
    loss = lovasz_softmax_flat(probs, labels, classes)
    (grad, ) = torch.autograd.grad(loss, logits, retain_graph=True)
    monkeypatch.setattr(torch, 'sort', real_sort)
    chosen = list(range(4) if classes == 'present' else range(5))
    expected = _lovasz_by_definition(probs, labels, chosen)
    (expected_grad, ) = torch.autograd.grad(expected, logits)
    torch.testing.assert_close(loss, expected, rtol=0, atol=1e-12)
    torch.testing.assert_close(grad, expected_grad, rtol=0, atol=1e-12)
    with torch.no_grad():
        wanted = []
        for c in chosen:
            errors = ((labels == c).double() - probs[:, c]).abs()
            members = errors[labels == c]
            cut = members.min() if len(members) else errors.max()
            wanted.append(int((errors >= cut).sum()))
    assert sizes == wanted
    assert wanted[-1] == (1 if classes == 'all' else wanted[-1])
    # 394 + 294 + 192 + 217 (+ 1) of 400 per class.
    assert sum(sizes) < 0.7 * 400 * len(chosen)


def test_lovasz_float32_matches_the_definition_at_scale():
    """The float32 path (errors sorted by their int32 bits, the loss as a
    product with fixed slopes) against Algorithm 1 on the same float32
    probabilities: 20,000 voxels of 5 classes, 90 % class 0, logits
    N(0, 1) plus 4 on the true class (each class holds confident members
    and near-zero errors, as a trained model's do). The loss to 1e-6; the
    gradient (entries up to ~1e-4: the slopes over 20k voxels) to 1e-8
    absolute: equal float32 errors of a member and a non-member may sort
    either way round in the reference, whose sort is not stable, which
    moves a few entries by ~2e-9."""
    gen = torch.Generator().manual_seed(5)
    labels = torch.multinomial(
        torch.tensor([0.9, 0.04, 0.03, 0.02, 0.01]), 20000,
        replacement=True, generator=gen)
    logits = torch.randn(20000, 5, generator=gen)
    logits[torch.arange(20000), labels] += 4.0
    logits.requires_grad_()
    loss = lovasz_softmax_flat(torch.softmax(logits, dim=1), labels)
    (grad, ) = torch.autograd.grad(loss, logits)
    expected = _lovasz_by_definition(
        torch.softmax(logits, dim=1), labels, range(5))
    (expected_grad, ) = torch.autograd.grad(expected, logits)
    assert loss.dtype == torch.float32
    torch.testing.assert_close(loss, expected, rtol=0, atol=1e-6)
    torch.testing.assert_close(grad, expected_grad, rtol=0, atol=1e-8)
    assert expected_grad.abs().max() > 1e-5
