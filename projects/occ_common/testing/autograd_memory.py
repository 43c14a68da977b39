"""What autograd keeps for the backward, for tests of memory savings."""
import weakref
from typing import Callable, List, Sequence, Tuple, TypeVar

import torch
from torch import Tensor
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

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


class _NewStorageBytes(TorchDispatchMode):
    """Live and peak bytes of the storages that ops create under it."""

    def __init__(self) -> None:
        super().__init__()
        self.live = self.peak = 0
        self._alive = {}

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        # Views, detaches and in-place ops return an input's storage.
        inputs = {
            t.untyped_storage().data_ptr()
            for t in tree_flatten((args, kwargs))[0]
            if isinstance(t, Tensor)
        }
        for tensor in tree_flatten(out)[0]:
            if not isinstance(tensor, Tensor):
                continue
            storage = tensor.untyped_storage()
            if id(storage) in self._alive or \
                    storage.data_ptr() in inputs:
                continue
            nbytes = storage.nbytes()
            self.live += nbytes
            self.peak = max(self.peak, self.live)
            self._alive[id(storage)] = weakref.finalize(
                storage, self._free, id(storage), nbytes)
        return out

    def _free(self, key: int, nbytes: int) -> None:
        self.live -= nbytes
        self._alive.pop(key, None)


def peak_new_bytes(run: Callable[[], T]) -> Tuple[T, int]:
    """Call ``run`` and measure the most bytes that tensors it created held
    at once (e.g. a backward's temporaries).

    Every storage an operator creates while ``run`` executes (backward
    formulas and custom ``Function`` backwards included) counts from its
    creation to its release; storages that existed before do not count.

    Args:
        run (Callable[[], T]): E.g. ``lambda: loss.backward()``.

    Returns:
        tuple: ``run``'s result and the peak bytes.
    """
    with _NewStorageBytes() as mode:
        out = run()
    return out, mode.peak
