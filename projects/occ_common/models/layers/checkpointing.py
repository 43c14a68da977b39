"""Activation checkpointing that switches itself off where it cannot help
and updates running statistics once."""
from typing import Callable, List, Optional, Tuple

import torch
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint


def checkpoint_if_grad(enabled: bool,
                       run: Callable[..., Tensor],
                       *args,
                       module: Optional[nn.Module] = None) -> Tensor:
    """``run(*args)``, recomputed in the backward when that saves memory.

    With ``enabled`` and a graph being built (grad mode on, and a tensor
    argument or a parameter of ``module`` that requires grad), only the
    arguments are kept and ``run`` is called again during the backward
    (non-reentrant ``torch.utils.checkpoint``, random state restored).
    Otherwise ``run`` is called plainly: under ``no_grad``, or when nothing
    upstream needs a gradient, there is nothing to save.

    The recomputation is exact for training BatchNorms too: it normalises
    with the batch statistics of the same input, and the buffers of
    ``module`` (running mean, variance, batch count) are put back after it,
    so they are updated once per forward, as without recomputation.
    ``mmdet``'s own ``with_cp`` (reentrant) updates them twice and skips a
    block whose input needs no gradient, such as the first block after a
    frozen stage.

    Args:
        enabled (bool): The module's ``with_cp``.
        run (Callable[..., Tensor]): A deterministic function of ``args``
            and of ``module``'s parameters and buffers.
        *args: Its arguments (tensors and plain values).
        module (nn.Module, optional): The module ``run`` evaluates: its
            parameters count as inputs, its buffers are restored after the
            recomputation. Defaults to None (``run`` changes no buffer).

    Returns:
        Tensor: ``run(*args)``.
    """
    if not (enabled and torch.is_grad_enabled()):
        return run(*args)
    needs_grad = any(
        isinstance(a, Tensor) and a.requires_grad for a in args) or (
            module is not None
            and any(p.requires_grad for p in module.parameters()))
    if not needs_grad:
        return run(*args)
    if module is None or next(module.buffers(), None) is None:
        return checkpoint(run, *args, use_reentrant=False)
    calls = []

    def run_once_updating_buffers(*inputs):
        if not calls:  # the forward: buffers update as usual
            calls.append(1)
            return run(*inputs)
        kept = _copy_buffers(module)  # a recomputation (possibly cut short)
        try:
            return run(*inputs)
        finally:
            _restore_buffers(kept)

    return checkpoint(run_once_updating_buffers, *args, use_reentrant=False)


def _copy_buffers(module: nn.Module) -> List[Tuple[Tensor, Tensor]]:
    """Every buffer of ``module`` with a copy of its current value."""
    return [(buf, buf.detach().clone()) for buf in module.buffers()]


def _restore_buffers(kept: List[Tuple[Tensor, Tensor]]) -> None:
    """Write the copies of :func:`_copy_buffers` back, in place."""
    with torch.no_grad():
        for buf, value in kept:
            buf.copy_(value)
