"""Activation checkpointing that switches itself off where it cannot help."""
from typing import Callable

import torch
from torch import Tensor
from torch.utils.checkpoint import checkpoint


def checkpoint_if_grad(enabled: bool, run: Callable[..., Tensor],
                       *args) -> Tensor:
    """``run(*args)``, recomputed in the backward when that saves memory.

    With ``enabled`` and a graph being built (grad mode on, a tensor
    argument that requires grad), only the arguments are kept and ``run``
    is called again during the backward (non-reentrant
    ``torch.utils.checkpoint``, random state restored). Otherwise ``run``
    is called plainly: under ``no_grad`` or for inputs without gradient
    there is nothing to save.

    Args:
        enabled (bool): The module's ``with_cp``.
        run (Callable[..., Tensor]): A deterministic function of ``args``.
        *args: Its arguments (tensors and plain values).

    Returns:
        Tensor: ``run(*args)``.
    """
    if enabled and torch.is_grad_enabled() and any(
            isinstance(a, Tensor) and a.requires_grad for a in args):
        return checkpoint(run, *args, use_reentrant=False)
    return run(*args)
