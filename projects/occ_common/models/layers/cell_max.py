"""Per-cell maximum of row features with a backward that stays small.

:func:`cell_max` is ``zeros.index_reduce_(0, cell, feats, 'amax',
include_self=False)`` (OccCylindrical's spatial group pooling and voxel
max pooling, the ``'max'`` BEV scatter of the sparse backends) with the
same values and, but for one case, the same gradient, bit for bit: rows of
one cell that tie exactly at its maximum share the cell's gradient
equally (torch's ``amax`` rule), and a cell no row reaches stays 0.

The case: where a cell's maximum is exactly 0, torch's backward also
counts the output's initial zero, which ``include_self=False`` kept out of
the maximum, as a tie, and the rows get only their share of a gradient
that is then thrown away (half, for a single winner). Here they get all
of it, as at any other value. In OccCylindrical a maximum of exactly 0
comes from post-ReLU LiDAR features, whose gradient the ReLU stops anyway.

Why not torch's own backward: for ``index_reduce`` it builds about four
temporaries of the output's size and four of the input's (the selected
maxima, two equality masks as floats, the tie counts, the shared gradient,
the gathered gradient), all alive at once. At OccCylindrical's Table VI
cylinder (480 x 368 x 32, M = 8, 64 channels) one (R, Theta) plane is
361 MiB and the occupied camera voxels about as much, so that backward
peaked ~3 GB above its inputs and set the training iteration's peak
memory (measured 2026-11-25, 1cff775). This one keeps one output-sized
float tensor (the tie counts, overwritten by the shared gradient), a
boolean mask of the rows at their cell's maximum (a quarter of the input's
bytes) and the gradient it returns; the float temporaries are made in
chunks of rows.
"""
import contextlib
import warnings
from typing import Iterator

import torch
from torch import Tensor
from torch.autograd import Function
from torch.autograd.function import once_differentiable

#: Rows per chunk of the backward's float temporaries: 64k rows of 64
#: channels are 16 MiB.
CHUNK_ROWS = 1 << 16


@contextlib.contextmanager
def quiet_index_reduce() -> Iterator[None]:
    """Silence torch's "index_reduce() is in beta" warning inside the block.

    Not while ``torch.compile`` traces: Dynamo cannot trace the warnings
    filter (a graph break), and the compiled kernel does not warn.
    """
    if torch.compiler.is_compiling():
        yield
        return
    with warnings.catch_warnings():
        warnings.filterwarnings('ignore', message='index_reduce')
        yield


def _amax_rows(feats: Tensor, cell: Tensor, num_cells: int) -> Tensor:
    """The forward: per-cell, per-channel maximum, 0 where no row goes."""
    with quiet_index_reduce():
        # In place on zeros: the out-of-place index_reduce would copy the
        # zeros first.
        return feats.new_zeros(num_cells, feats.shape[1]).index_reduce_(
            0, cell, feats, 'amax', include_self=False)


class CellMaxFunction(Function):
    """Autograd function of :func:`cell_max` (see the module doc)."""

    @staticmethod
    def forward(ctx, feats: Tensor, cell: Tensor, num_cells: int) -> Tensor:
        out = _amax_rows(feats, cell, num_cells)
        ctx.save_for_backward(feats, cell, out)
        return out

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_out: Tensor):
        feats, cell, out = ctx.saved_tensors
        grad_out = grad_out.contiguous()
        # Compiled code makes no chunks: their number would fix the row
        # count (a dynamic size under torch.compile) to the one traced,
        # and the compiler fuses the temporaries away anyway.
        chunks = ([(0, feats.shape[0])] if torch.compiler.is_compiling()
                  else [(start, min(start + CHUNK_ROWS, feats.shape[0]))
                        for start in range(0, feats.shape[0], CHUNK_ROWS)])
        at_max = torch.empty_like(feats, dtype=torch.bool)
        for start, end in chunks:
            torch.eq(feats[start:end],
                     out.index_select(0, cell[start:end]),
                     out=at_max[start:end])
        # How many rows share each maximum, then the share of each (as
        # torch: grad / N, times the 0/1 mask); cells no row reaches get
        # a 0 / 0 that no row ever reads.
        share = torch.zeros_like(out)
        for start, end in chunks:
            share.index_add_(0, cell[start:end],
                             at_max[start:end].to(feats.dtype))
        torch.div(grad_out, share, out=share)
        grad_feats = torch.empty_like(feats)
        for start, end in chunks:
            torch.mul(
                share.index_select(0, cell[start:end]),
                at_max[start:end],
                out=grad_feats[start:end])
        return grad_feats, None, None


def cell_max(feats: Tensor, cell: Tensor, num_cells: int) -> Tensor:
    """Maximum of the rows of each cell, channel by channel.

    Args:
        feats (Tensor): Row features. Shape (U, C).
        cell (Tensor): Cell of each row, int64 in ``[0, num_cells)``.
            Shape (U, ).
        num_cells (int): Number of cells ``O``.

    Returns:
        Tensor: Per-cell maxima, 0 for a cell no row reaches.
        Shape (O, C).
    """
    if feats.dim() != 2 or cell.shape != feats.shape[:1]:
        raise ValueError('cell_max expects feats (U, C) and cell (U,), got '
                         f'{tuple(feats.shape)} and {tuple(cell.shape)}')
    if torch.is_grad_enabled() and feats.requires_grad:
        return CellMaxFunction.apply(feats, cell, num_cells)
    return _amax_rows(feats, cell, num_cells)
