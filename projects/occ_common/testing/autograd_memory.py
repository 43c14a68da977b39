"""What autograd keeps for the backward, for tests of memory savings."""
from typing import Callable, Tuple, TypeVar

import torch

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
