"""Inverse of 4x4 matrices that also exports to ONNX.

ONNX's default domain has no matrix inverse (onnxruntime's ``Inverse`` is
a contrib operator that TensorRT and most runtimes lack), so
``torch.linalg.inv`` stops the exporter. :func:`inverse_4x4` is the closed
form of the adjugate (the 2x2 minors of the top and bottom row pairs,
Laplace's expansion), a few dozen multiplications that every runtime has;
:func:`invert_matrix` takes it while a graph is being exported and
``torch.linalg.inv`` otherwise, so eager outputs stay bit for bit those of
``torch.linalg.inv``.
"""
import torch
from torch import Tensor


def inverse_4x4(mat: Tensor) -> Tensor:
    """Closed-form inverse of invertible 4x4 matrices.

    ``adj(A) / det(A)`` from the six 2x2 minors ``s`` of rows 0-1 and the
    six ``c`` of rows 2-3: ``det = s0 c5 - s1 c4 + s2 c3 + s3 c2 - s4 c1 +
    s5 c0``. Any invertible matrix (projective, not only rigid); in the
    dtype of ``mat``, so callers that need the far depth bins accurate pass
    float64 as they do to ``torch.linalg.inv``.

    Args:
        mat (Tensor): Matrices. Shape (..., 4, 4).

    Returns:
        Tensor: Their inverses. Shape (..., 4, 4).
    """
    if mat.shape[-2:] != (4, 4):
        raise ValueError(f'inverse_4x4 expects (..., 4, 4), got '
                         f'{tuple(mat.shape)}')
    (a00, a01, a02, a03, a10, a11, a12, a13, a20, a21, a22, a23, a30, a31,
     a32, a33) = mat.flatten(-2).unbind(-1)
    s0 = a00 * a11 - a10 * a01
    s1 = a00 * a12 - a10 * a02
    s2 = a00 * a13 - a10 * a03
    s3 = a01 * a12 - a11 * a02
    s4 = a01 * a13 - a11 * a03
    s5 = a02 * a13 - a12 * a03
    c0 = a20 * a31 - a30 * a21
    c1 = a20 * a32 - a30 * a22
    c2 = a20 * a33 - a30 * a23
    c3 = a21 * a32 - a31 * a22
    c4 = a21 * a33 - a31 * a23
    c5 = a22 * a33 - a32 * a23
    det = s0 * c5 - s1 * c4 + s2 * c3 + s3 * c2 - s4 * c1 + s5 * c0
    adj = torch.stack([
        a11 * c5 - a12 * c4 + a13 * c3,
        -a01 * c5 + a02 * c4 - a03 * c3,
        a31 * s5 - a32 * s4 + a33 * s3,
        -a21 * s5 + a22 * s4 - a23 * s3,
        -a10 * c5 + a12 * c2 - a13 * c1,
        a00 * c5 - a02 * c2 + a03 * c1,
        -a30 * s5 + a32 * s2 - a33 * s1,
        a20 * s5 - a22 * s2 + a23 * s1,
        a10 * c4 - a11 * c2 + a13 * c0,
        -a00 * c4 + a01 * c2 - a03 * c0,
        a30 * s4 - a31 * s2 + a33 * s0,
        -a20 * s4 + a21 * s2 - a23 * s0,
        -a10 * c3 + a11 * c1 - a12 * c0,
        a00 * c3 - a01 * c1 + a02 * c0,
        -a30 * s3 + a31 * s1 - a32 * s0,
        a20 * s3 - a21 * s1 + a22 * s0,
    ], dim=-1)
    return (adj / det.unsqueeze(-1)).unflatten(-1, (4, 4))


def invert_matrix(mat: Tensor) -> Tensor:
    """``torch.linalg.inv``, or :func:`inverse_4x4` while exporting.

    Args:
        mat (Tensor): Invertible matrices. Shape (..., 4, 4).

    Returns:
        Tensor: Their inverses, the dtype of ``mat``. Shape (..., 4, 4).
    """
    if torch.onnx.is_in_onnx_export():
        return inverse_4x4(mat)
    return torch.linalg.inv(mat)
