"""Count what a GPU pays for, on any device: kernel launches and host syncs.

On a GPU every aten operator that computes (not a view, not an
allocation) is at least one kernel launch, ~5-20 us of host time however
small the tensor; an operator whose result size or value the host must
know (``nonzero``, boolean-mask indexing, ``unique``, ``.item()``,
``.tolist()``, ``torch.equal``...) makes the host wait for the device. Both
are properties of the code path, so they can be counted on the CPU, where
the same operators are dispatched. :class:`OpCounter` counts them under a
``TorchDispatchMode`` (operators after autograd, so the backward's too)
and a ``TorchFunctionMode`` (the Python-level reads that dispatch nothing
on the CPU: ``tolist``, ``numpy``), and attributes each to a top-level
module of a model and to the forward, the backward or neither (the
optimiser step):

* forward: the innermost top-level module whose ``forward`` is running
  (``(model)`` for the detector's own code between them, and for a child
  called through another method, e.g. a head's ``predict``);
* backward: the module whose forward created the autograd node being
  run (``torch._C._current_autograd_node``), found by walking each
  module's outputs' graph back to the nodes an earlier module created;
  nodes created during a recomputation in the backward take the module of
  the last attributed node;
* ``(optimizer)``: inside :meth:`OpCounter.optimizer_step`.

Counted as launches: every operator but those of :data:`NO_KERNEL_OPS`
(views, metadata, allocations) and of :data:`SYNC_ONLY_OPS` (a device
read, counted as a sync). Counted as syncs: :data:`SYNC_OPS`, an
``index`` / ``index_put`` with a boolean index (its ``nonzero``), and the
Python-level reads of :data:`SYNC_METHODS`. ``lift_fresh`` (a tensor made
from host data, e.g. ``torch.tensor([...])``) is counted as ``host_data``:
on a GPU it is followed by a host-to-device copy.
"""
import contextlib
from collections import defaultdict
from typing import Dict, Iterable, Iterator, List, Optional

import torch
from torch import nn
from torch.overrides import TorchFunctionMode
from torch.utils._python_dispatch import TorchDispatchMode

#: Operators that launch no kernel: views, shape and metadata operations,
#: allocations without initialisation.
NO_KERNEL_OPS = frozenset({
    'view', '_unsafe_view', 'expand', 'permute', 'transpose', 't',
    'unsqueeze', 'squeeze', 'as_strided', 'slice', 'select', 'detach',
    'alias', 'unbind', 'split', 'split_with_sizes', 'unflatten',
    '_reshape_alias', 'diagonal', 'view_as_real', 'view_as_complex',
    'empty', 'empty_strided', 'empty_like', 'new_empty',
    'new_empty_strided', 'lift_fresh', 'set_', 'resize_', 'unsqueeze_',
    'squeeze_', 't_', 'transpose_', 'as_strided_', 'is_same_size',
    '_has_compatible_shallow_copy_type', 'sym_size', 'sym_stride',
    'sym_numel', 'sym_storage_offset', 'is_contiguous', 'dim', 'size',
    'stride', 'numel', 'storage_offset', 'output_nr', '_version',
    'is_nonzero', 'prim_layout', 'prim_device', '_record_function_enter',
    '_record_function_enter_new', '_record_function_exit'
})
#: Operators whose result the host must wait for (and that also launch).
SYNC_OPS = frozenset({
    'nonzero', 'masked_select', 'unique', '_unique', '_unique2',
    'unique_consecutive', 'unique_dim', 'equal', 'bincount',
    'repeat_interleave'  # unless output_size is given
})
#: Device reads that launch nothing themselves: counted as a sync only.
SYNC_ONLY_OPS = frozenset({'_local_scalar_dense'})
#: Python-level reads that dispatch nothing on the CPU but copy the
#: tensor to the host on a GPU.
SYNC_METHODS = frozenset({'tolist', 'numpy'})
#: Operators that make a tensor of host data.
HOST_DATA_OPS = frozenset({'lift_fresh', 'lift_fresh_copy'})


def _op_name(func) -> str:
    """``aten.index.Tensor`` -> ``'index'``."""
    return func.overloadpacket.__name__ if hasattr(
        func, 'overloadpacket') else getattr(func, '__name__', str(func))


def _has_bool_index(args) -> bool:
    indices = args[1] if len(args) > 1 else ()
    return any(
        isinstance(t, torch.Tensor) and t.dtype in (torch.bool, torch.uint8)
        for t in (indices or ()) if t is not None)


def _tensors(value) -> Iterable[torch.Tensor]:
    if isinstance(value, torch.Tensor):
        yield value
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _tensors(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _tensors(v)


class _Counts:
    """Launches, syncs and host-data tensors of one (module, phase)."""

    def __init__(self) -> None:
        self.launches = 0
        self.syncs = 0
        self.host_data = 0
        self.ops: Dict[str, int] = defaultdict(int)


class _DispatchCounter(TorchDispatchMode):

    def __init__(self, owner: 'OpCounter') -> None:
        super().__init__()
        self.owner = owner

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.owner.record(func, args, kwargs or {})
        return func(*args, **(kwargs or {}))


class _FunctionCounter(TorchFunctionMode):

    def __init__(self, owner: 'OpCounter') -> None:
        super().__init__()
        self.owner = owner

    def __torch_function__(self, func, types, args=(), kwargs=None):
        if getattr(func, '__name__', '') in SYNC_METHODS:
            self.owner.count(syncs=1, op=f'{func.__name__}()')
        return func(*args, **(kwargs or {}))


class OpCounter:
    """Count launches and syncs of a model's calls, per top-level module.

    Use as a context manager around a prediction or a training step::

        counter = OpCounter(model)
        with counter:
            model.train_step(batch, optim_wrapper)
        counter.table()   # rows per (module, phase)

    Args:
        model (nn.Module): Its direct children are the rows.
    """

    def __init__(self, model: nn.Module) -> None:
        self.model = model
        self.counts: Dict[tuple, _Counts] = defaultdict(_Counts)
        self._stack: List[str] = []
        self._node_module: Dict[object, str] = {}
        self._last_backward = '(model)'
        self._hooks: list = []
        self._modes: list = []
        self._marked: Optional[str] = None

    @contextlib.contextmanager
    def optimizer_step(self) -> Iterator[None]:
        """Attribute what runs inside to ``(optimizer)``, where reading a
        0-dim tensor is not a sync: torch optimisers keep their step
        counts on the host for CUDA parameters (unless ``capturable`` or
        ``fused``), so those reads never wait for the device."""
        before, self._marked = self._marked, '(optimizer)'
        try:
            yield
        finally:
            self._marked = before

    # -- attribution ---------------------------------------------------
    def _phase_module(self):
        if self._marked is not None:
            return self._marked, 'optimizer'
        node = torch._C._current_autograd_node()
        if node is not None:
            module = self._node_module.get(node)
            if module is None:
                module = self._last_backward
            self._last_backward = module
            return module, 'backward'
        if self._stack:
            return self._stack[-1], 'forward'
        return '(outside)', 'other'

    def count(self, launches: int = 0, syncs: int = 0, host_data: int = 0,
              op: Optional[str] = None) -> None:
        """Add to the current (module, phase)."""
        entry = self.counts[self._phase_module()]
        entry.launches += launches
        entry.syncs += syncs
        entry.host_data += host_data
        if op is not None:
            entry.ops[op] += 1

    def record(self, func, args, kwargs=None) -> None:
        """Classify one dispatched operator."""
        name = _op_name(func)
        if name == 'repeat_interleave' and (kwargs or {}).get(
                'output_size') is not None:
            # The output size given: nothing for the host to wait for.
            self.count(launches=1, op=name)
            return
        if name in HOST_DATA_OPS:
            self.count(host_data=1, op=name)
        elif name in SYNC_ONLY_OPS:
            host_scalar = (self._marked is not None and args
                           and isinstance(args[0], torch.Tensor)
                           and args[0].dim() == 0)
            if host_scalar:
                self.count(op='host step count read')
            else:
                self.count(syncs=1, op=name)
        elif name in NO_KERNEL_OPS:
            return
        elif name in SYNC_OPS or (name in ('index', 'index_put', 'index_put_')
                                  and _has_bool_index(args)):
            self.count(launches=1, syncs=1, op=name)
        else:
            self.count(launches=1, op=name)

    def _claim(self, outputs, module: str) -> None:
        """Give ``module`` the autograd nodes its outputs reach that no
        earlier module created."""
        todo = [t.grad_fn for t in _tensors(outputs) if t.grad_fn is not None]
        while todo:
            node = todo.pop()
            if node is None or node in self._node_module:
                continue
            self._node_module[node] = module
            todo.extend(n for n, _ in node.next_functions if n is not None)

    # -- context -------------------------------------------------------
    def __enter__(self) -> 'OpCounter':
        for name, child in self.model.named_children():
            self._hooks.append(child.register_forward_pre_hook(
                lambda mod, inp, name=name: self._stack.append(name)))
            self._hooks.append(child.register_forward_hook(
                lambda mod, inp, out, name=name: self._leave(name, out)))
        self._hooks.append(self.model.register_forward_pre_hook(
            lambda mod, inp: self._stack.append('(model)')))
        self._hooks.append(self.model.register_forward_hook(
            lambda mod, inp, out: self._leave('(model)', out)))
        self._modes = [_FunctionCounter(self), _DispatchCounter(self)]
        for mode in self._modes:
            mode.__enter__()
        return self

    def _leave(self, name: str, outputs) -> None:
        self._claim(outputs, name)
        if self._stack and self._stack[-1] == name:
            self._stack.pop()

    def __exit__(self, *exc) -> None:
        for mode in reversed(self._modes):
            mode.__exit__(*exc)
        for hook in self._hooks:
            hook.remove()
        self._hooks, self._modes = [], []
        self._node_module.clear()

    # -- results -------------------------------------------------------
    def table(self) -> List[Dict]:
        """One row per (module, phase), largest launch count first."""
        rows = [
            dict(module=module, phase=phase, launches=c.launches,
                 syncs=c.syncs, host_data=c.host_data,
                 top_ops=dict(sorted(c.ops.items(),
                                     key=lambda kv: -kv[1])[:5]))
            for (module, phase), c in self.counts.items()
        ]
        return sorted(rows, key=lambda r: (-r['launches'], r['module']))

    def totals(self) -> Dict[str, int]:
        """Launches, syncs and host-data tensors over everything."""
        return dict(
            launches=sum(c.launches for c in self.counts.values()),
            syncs=sum(c.syncs for c in self.counts.values()),
            host_data=sum(c.host_data for c in self.counts.values()))
