"""The closed-form 4x4 inverse that replaces ``torch.linalg.inv`` in
exported graphs."""
import pytest
import torch
from torch import nn

from projects.occ_common.geometry.inverse import inverse_4x4, invert_matrix
from projects.occ_common.synthetic.synthetic_batch import ring_rig


def test_hand_made_projective_matrix():
    """A scale, a shear-free projection row and a translation.

    A = [[2, 0, 0, 4], [0, 4, 0, 8], [0, 0, 5, 10], [0, 0, 0, 1]]: the
    inverse scales by 1/2, 1/4, 1/5 and translates by -4/2 = -2,
    -8/4 = -2, -10/5 = -2.
    """
    mat = torch.tensor([[2., 0, 0, 4], [0, 4, 0, 8], [0, 0, 5, 10],
                        [0, 0, 0, 1]], dtype=torch.float64)
    expected = torch.tensor([[0.5, 0, 0, -2], [0, 0.25, 0, -2],
                             [0, 0, 0.2, -2], [0, 0, 0, 1]],
                            dtype=torch.float64)
    torch.testing.assert_close(inverse_4x4(mat), expected)


def test_matches_linalg_inv_on_camera_matrices():
    """``img_aug @ cam2img @ lidar2cam`` of a ring rig with a flipped
    augmentation, and random well-conditioned matrices, batched."""
    rig = ring_rig(6, (128, 352))
    flip = torch.eye(4, dtype=torch.float64)
    flip[0, 0], flip[0, 2] = -1, 352
    lidar2img = flip @ torch.as_tensor(rig['lidar2img']).double()
    gen = torch.Generator().manual_seed(0)
    rand = torch.randn(2, 3, 4, 4, generator=gen, dtype=torch.float64) + \
        4 * torch.eye(4, dtype=torch.float64)
    for mat in (lidar2img, rand):
        torch.testing.assert_close(
            inverse_4x4(mat), torch.linalg.inv(mat), rtol=1e-10, atol=1e-12)


def test_eager_calls_are_linalg_inv_bit_for_bit():
    mat = torch.as_tensor(ring_rig(3, (64, 96))['lidar2img']).double()
    assert torch.equal(invert_matrix(mat), torch.linalg.inv(mat))


def test_wrong_shape_is_refused():
    with pytest.raises(ValueError, match=r'\(\.\.\., 4, 4\)'):
        inverse_4x4(torch.eye(3))


class _Inverse(nn.Module):

    def forward(self, mat):
        return invert_matrix(mat.double()).float()


def test_exported_graph_has_no_inverse_operator(tmp_path):
    """ONNX's default domain has no inverse: the graph is the closed form,
    and onnxruntime agrees with ``torch.linalg.inv`` on another matrix
    than the one it was traced with."""
    from projects.occ_common.deployment import (export_graph, graph_summary,
                                                onnx_session, run_graph)
    rig = torch.as_tensor(ring_rig(6, (128, 352))['lidar2img'])
    path = export_graph(_Inverse(), [rig], str(tmp_path / 'inv.onnx'),
                        ['mat'], ['inv'])
    assert 'Inverse' not in graph_summary(path)['ops']
    other = rig.clone()
    other[:, :3, 3] += torch.tensor([0.5, -1.0, 2.0])
    got = run_graph(onnx_session(path), dict(mat=other))['inv']
    torch.testing.assert_close(
        torch.from_numpy(got), torch.linalg.inv(other.double()).float())
