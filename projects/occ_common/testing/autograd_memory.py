"""What autograd keeps for the backward, for tests of memory savings."""
from typing import Callable, List, Sequence, Tuple, TypeVar

import torch
from torch import Tensor

T = TypeVar('T')


def saved_tensor_bytes(run: Callable[[], T]) -> Tuple[T, int]:
    """Call ``run`` and count the bytes its graph saves for the backward.

    Every tensor autograd packs while ``run`` builds its graph is counted
    by its storage, each storage once (views of one tensor share it).

    Args:
        run (Callable[[], T]): Builds the graph, e.g. a forward pass.

    Returns:
        tuple: ``run``'s result and the saved bytes.
    """
    storages = {}

    def pack(tensor):
        storage = tensor.untyped_storage()
        storages[storage.data_ptr()] = storage.nbytes()
        return tensor

    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        out = run()
    return out, sum(storages.values())


def recorded_training_step(module: torch.nn.Module, hooked: torch.nn.Module,
                           forward: Callable[[], Sequence[Tensor]],
                           extra: Callable[[], List[Tensor]] = list
                           ) -> Tuple[List[Tensor], int, List[tuple]]:
    """One forward and backward of ``module``, recorded for comparing a
    recomputed (``with_cp``) path with the plain one.

    Args:
        module (torch.nn.Module): The module trained; its parameter
            gradients and buffers are collected after the backward.
        hooked (torch.nn.Module): A submodule whose calls are counted
            (once in the forward, once more per recomputation).
        forward (Callable[[], Sequence[Tensor]]): Runs the forward and
            returns the outputs; the backward is taken of the sum of
            every output times itself.
        extra (Callable[[], list[Tensor]]): Further tensors to compare,
            read after the backward (e.g. an input's gradient).

    Returns:
        tuple: The values (outputs, ``extra()``, parameter gradients,
        buffers), the number of calls of ``hooked`` and the shapes of the
        tensors packed for the backward during the forward.
    """
    calls, shapes = [], []
    handle = hooked.register_forward_pre_hook(lambda *a: calls.append(1))

    def pack(tensor):
        shapes.append(tuple(tensor.shape))
        return tensor

    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        outs = list(forward())
    sum((out * out).sum() for out in outs).backward()
    handle.remove()
    values = ([out.detach() for out in outs] + list(extra()) +
              [p.grad for p in module.parameters()] +
              [b.clone() for b in module.buffers()])
    return values, len(calls), shapes


def same_weights_pair(reference_type: type, recomputed_type: type,
                      reference_with_cp: bool = False,
                      **kwargs) -> Tuple[torch.nn.Module, torch.nn.Module]:
    """An mmdet backbone and its recomputed subclass with the same
    weights, both float64 and in training mode.

    Args:
        reference_type (type): The mmdet class, e.g. ``ResNet``.
        recomputed_type (type): Its recomputed subclass, built with
            ``with_cp=True``.
        reference_with_cp (bool): The reference's own ``with_cp``.
            Defaults to False.
        **kwargs: Constructor arguments of both.

    Returns:
        tuple: The reference and the recomputed module.
    """
    torch.manual_seed(0)
    reference = reference_type(with_cp=reference_with_cp, **kwargs).double()
    recomputed = recomputed_type(with_cp=True, **kwargs).double()
    recomputed.load_state_dict(reference.state_dict())
    reference.train()  # mmdet's train() returns None: not chained
    recomputed.train()
    return reference, recomputed
