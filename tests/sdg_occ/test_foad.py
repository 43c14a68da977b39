"""Tests of ``foad_weights`` and ``FOADDistillLoss``."""
import pytest
import torch

from projects.sdg_occ import FOADDistillLoss, foad_weights
from projects.sdg_occ.foad import standardize_channels


def _masks():
    """Sample 0 (2 x 3): fused [[1,1,1],[1,0,0]], img [[1,0,0],[0,0,1]].
    Sample 1: fused and img everywhere."""
    fused = torch.tensor([[[1, 1, 1], [1, 0, 0]], [[1, 1, 1], [1, 1, 1]]],
                         dtype=torch.bool).unsqueeze(1)
    img = torch.tensor([[[1, 0, 0], [0, 0, 1]], [[1, 1, 1], [1, 1, 1]]],
                       dtype=torch.bool).unsqueeze(1)
    return fused, img


def test_weights_by_hand():
    """alpha = 2, beta = 0.6.

    Sample 0: AR = {(0,0)} (N_AR = 1), IR = {(0,1), (0,2), (1,0)}
    (N_IR = 3), rho = 1/3 -> IR weight 0.6 / 3 = 0.2; (1,2) is img-only and
    (1,1) covered by neither -> 0.
    Sample 1: AR = all 6 cells, IR empty -> weight 2 everywhere.
    """
    fused, img = _masks()
    w = foad_weights(fused, img, alpha=2.0, beta=0.6)
    expected = torch.tensor([[[2.0, 0.2, 0.2], [0.2, 0.0, 0.0]],
                             [[2.0] * 3, [2.0] * 3]]).unsqueeze(1)
    assert torch.allclose(w, expected)


def test_weights_no_active_region():
    """Nothing seen by the camera: N_AR = 0 -> rho = 0, all weights 0."""
    fused = torch.ones(1, 1, 2, 2, dtype=torch.bool)
    img = torch.zeros(1, 1, 2, 2, dtype=torch.bool)
    assert torch.equal(foad_weights(fused, img, 1.0, 1.0),
                       torch.zeros(1, 1, 2, 2))


def test_loss_value_detached_teacher_and_student_grad():
    """Student 0, teacher 1, C = 2 channels, alpha = 2, beta = 0.6.

    Numerator: sample 0 sum W = 2 + 3 * 0.2 = 2.6, sample 1 sum W = 12,
    each times C = 2 channels and (1 - 0)^2 = 1 -> 2 * (2.6 + 12) = 29.2.
    Denominator C * N_fused = 2 * (4 + 6) = 20. Loss = 0.5 * 29.2 / 20 =
    0.73 with loss_weight 0.5. d loss / d S = 0.5 * -2 W (T - S) / 20 =
    -W / 20, e.g. -0.1 at a weight-2 cell and -0.01 at a weight-0.2 cell.
    """
    fused, img = _masks()
    student = torch.zeros(2, 2, 2, 3, requires_grad=True)
    teacher = torch.ones(2, 2, 2, 3, requires_grad=True)
    loss_fn = FOADDistillLoss(alpha=2.0, beta=0.6, loss_weight=0.5)
    loss = loss_fn(student, teacher, fused, img)
    assert torch.isclose(loss, torch.tensor(0.73))
    loss.backward()
    assert teacher.grad is None  # one-way: the teacher is detached
    weights = foad_weights(fused, img, 2.0, 0.6).expand(-1, 2, -1, -1)
    assert torch.allclose(student.grad, -weights / 20)
    assert torch.isclose(student.grad[0, 0, 0, 1], torch.tensor(-0.01))


def test_empty_fused_mask_gives_zero_loss_with_grad():
    """No teacher cell: W = 0, denominator clamped to 1, loss 0."""
    student = torch.randn(1, 3, 2, 2, requires_grad=True)
    teacher = torch.randn(1, 3, 2, 2)
    empty = torch.zeros(1, 1, 2, 2, dtype=torch.bool)
    loss = FOADDistillLoss()(student, teacher, empty, empty)
    assert loss.item() == 0.0
    loss.backward()
    assert torch.equal(student.grad, torch.zeros(1, 3, 2, 2))


def test_bad_inputs_raise():
    fused, img = _masks()
    with pytest.raises(ValueError, match=r'\(B, 1, H, W\)'):
        foad_weights(fused[:, 0], img, 1.0, 1.0)
    with pytest.raises(ValueError, match='same shape'):
        foad_weights(fused, img[:1], 1.0, 1.0)
    with pytest.raises(ValueError, match='student and teacher'):
        FOADDistillLoss()(
            torch.zeros(2, 2, 2, 3), torch.zeros(2, 1, 2, 3), fused, img)
    with pytest.raises(ValueError, match='masks must be'):
        FOADDistillLoss()(
            torch.zeros(2, 2, 2, 2), torch.zeros(2, 2, 2, 2), fused, img)


def test_standardize_channels_by_hand():
    """One channel 1, 3, 5, 100 on a 1 x 4 map, the last cell outside.

    Over the three cells: mean 3, variance (4 + 0 + 4) / 3 = 8 / 3, so
    1 -> -2 / sqrt(8/3) = -1.2247, 3 -> 0, 5 -> 1.2247, and the outside
    cell is shifted and scaled alike: 97 / sqrt(8/3) = 59.4001.
    """
    feats = torch.tensor([1.0, 3.0, 5.0, 100.0]).view(1, 1, 1, 4)
    cells = torch.tensor([True, True, True, False]).view(1, 1, 1, 4)
    out = standardize_channels(feats, cells, eps=0.0)
    expected = torch.tensor([-1.2247, 0.0, 1.2247, 59.4001]).view(1, 1, 1, 4)
    torch.testing.assert_close(out, expected, atol=1e-4, rtol=0)


def test_channel_normalisation_compares_patterns_not_scales():
    """A student that is the teacher times 4.2 plus 3 per channel (the
    scale gap the tiny SDG-KL starts with) costs 0 once standardised;
    as written, eq. 8 charges mean((3.2 T + 3)^2) for it. A student of
    the teacher's sign flipped costs the largest value, 2 (1 - (-1)) = 4
    on every active cell and channel (alpha 1, no inactive cell)."""
    gen = torch.Generator().manual_seed(0)
    teacher = torch.rand(2, 3, 4, 5, generator=gen)
    cells = torch.ones(2, 1, 4, 5, dtype=torch.bool)
    scaled = 4.2 * teacher + 3.0
    normalised = FOADDistillLoss(normalize='channel')
    assert normalised(scaled, teacher, cells, cells).item() < 1e-4
    raw = FOADDistillLoss()(scaled, teacher, cells, cells)
    torch.testing.assert_close(raw, (3.2 * teacher + 3.0).pow(2).mean())
    flipped = normalised(-teacher, teacher, cells, cells)
    torch.testing.assert_close(flipped, torch.tensor(4.0), atol=1e-3,
                               rtol=0)


def test_channel_statistics_come_from_the_teacher_cells_only():
    """Cells outside the fused mask change neither the statistics nor the
    loss: a student equal to the teacher there, anything elsewhere."""
    fused, img = _masks()
    gen = torch.Generator().manual_seed(1)
    teacher = torch.randn(2, 2, 2, 3, generator=gen)
    student = teacher.clone()
    student[~fused.expand(-1, 2, -1, -1)] = 1e3
    loss = FOADDistillLoss(normalize='channel')(student, teacher, fused,
                                                img)
    assert loss.item() < 1e-6
    with pytest.raises(ValueError, match="normalize must be one of"):
        FOADDistillLoss(normalize='batch')
