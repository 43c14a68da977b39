"""Export a module to ONNX, run it with onnxruntime, compare with PyTorch.

The export takes the GPU code path of
:mod:`projects.occ_common.utils.device_path` (no data-dependent shapes:
scatters over a fixed number of slots instead of sorts and ``nonzero``)
and the TorchScript-based exporter (``dynamo=False``), which writes
``scatter_reduce`` and ``scatter_add`` as ``ScatterElements`` with their
reduction. ``onnx`` and ``onnxruntime`` are imported only when needed
(requirements/tests.txt pins them).
"""
import os
import os.path as osp
import warnings
from collections import Counter
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np
import torch
from torch import Tensor, nn

from ..utils.device_path import forced_accelerator_path
from .deform_conv import (DEFORM_CONV_OPSET, deformable_convs,
                          exportable_deform_convs)

#: Opset of the exported graphs: ``ScatterElements(reduction='max' /
#: 'min')`` needs 18; a graph with deformable convolutions gets
#: :data:`~.deform_conv.DEFORM_CONV_OPSET` (19, ``DeformConv``).
DEFAULT_OPSET = 18


def export_graph(module: nn.Module,
                 args: Sequence[Tensor],
                 path: str,
                 input_names: Sequence[str],
                 output_names: Sequence[str],
                 dynamic_axes: Optional[Mapping[str, Mapping[int,
                                                             str]]] = None,
                 opset: Optional[int] = None) -> str:
    """Trace ``module(*args)`` on the GPU code path and write ONNX.

    Args:
        module (nn.Module): The module; it is put in eval mode.
        args (Sequence[Tensor]): One example of every input.
        path (str): Output file; its folder is created.
        input_names (Sequence[str]): Names of ``args``.
        output_names (Sequence[str]): Names of the outputs.
        dynamic_axes (Mapping, optional): Input / output name -> axis ->
            symbolic name, e.g. ``{'points': {0: 'num_points'}}``.
            Defaults to None (all static).
        opset (int, optional): ONNX opset. Defaults to
            :func:`required_opset`'s, lowered to :data:`DEFAULT_OPSET`
            when the traced graph holds no ``DeformConv`` (the module's
            deformable convolutions are not called).

    Returns:
        str: ``path``.

    Raises:
        ValueError: An opset below 19 for a module with deformable
            convolutions (ONNX ``DeformConv``), naming them.
    """
    requested, needed = opset, required_opset(module)
    opset = needed if opset is None else int(opset)
    if opset < needed:
        names = deformable_convs(module)
        raise ValueError(
            f'{len(names)} deformable convolutions (mmcv DCN), e.g. '
            f'{names[:3]}, export as ONNX DeformConv, which needs opset '
            f'{DEFORM_CONV_OPSET}; got opset {opset}')
    # The exporter restores the module's mode afterwards: a wrapper left in
    # training mode would put the whole model back into it.
    module.eval()
    folder = osp.dirname(osp.abspath(path))
    os.makedirs(folder, exist_ok=True)
    _trace(module, args, path, input_names, output_names, dynamic_axes,
           opset)
    if (requested is None and opset > DEFAULT_OPSET
            and 'DeformConv' not in graph_summary(path)['ops']):
        # The module holds deformable convolutions its forward does not
        # call (a graph of one part of a model, as OccCylindrical's plane
        # graph): traced again at the default opset, which more runtimes
        # read.
        opset = DEFAULT_OPSET
        _trace(module, args, path, input_names, output_names, dynamic_axes,
               opset)
    constants_to_initializers(path)
    return path


def _trace(module: nn.Module, args: Sequence[Tensor], path: str,
           input_names: Sequence[str], output_names: Sequence[str],
           dynamic_axes: Optional[Mapping], opset: int) -> None:
    """``torch.onnx.export`` of ``module(*args)`` on the GPU code path, its
    deformable convolutions as ONNX ``DeformConv``."""
    torch.onnx.register_custom_op_symbolic('aten::hypot', _hypot, opset)
    with torch.no_grad(), forced_accelerator_path(True), \
            exportable_deform_convs(module), warnings.catch_warnings():
        # The legacy exporter's deprecation notice, the tracer's notes on
        # Python values (shapes and sizes, static by design) and
        # index_add's duplicate-index warning (only index_copy remains,
        # whose indices are distinct).
        warnings.simplefilter('ignore')
        torch.onnx.export(
            module,
            tuple(args),
            path,
            input_names=list(input_names),
            output_names=list(output_names),
            dynamic_axes=dict(dynamic_axes or {}),
            opset_version=int(opset),
            do_constant_folding=True,
            dynamo=False)


def required_opset(module: nn.Module) -> int:
    """The lowest opset :func:`export_graph` writes ``module`` with:
    :data:`DEFAULT_OPSET`, or ``DeformConv``'s 19 when it holds mmcv's
    deformable convolutions."""
    return DEFORM_CONV_OPSET if deformable_convs(module) else DEFAULT_OPSET


def _hypot(g, x, y):
    """``aten::hypot`` (the cylindrical radius), which the exporter lacks,
    as ``sqrt(x * x + y * y)``: the same in float32 for coordinates of a
    few hundred metres (hypot only differs where x * x overflows)."""
    return g.op('Sqrt', g.op('Add', g.op('Mul', x, x), g.op('Mul', y, y)))


def constants_to_initializers(path: str) -> int:
    """Move the graph's ``Constant`` nodes into its initializers, in place.

    The TorchScript exporter writes every slice bound and shape as a
    ``Constant`` node (a third of the nodes of our graphs); as
    initializers they are the same tensors, the graph computes the same,
    and the node count is that of the operations.

    Args:
        path (str): An ONNX file, rewritten.

    Returns:
        int: The number of nodes moved.
    """
    import onnx
    model = onnx.load(path)
    kept, moved = [], 0
    for node in model.graph.node:
        value = [a for a in node.attribute if a.name == 'value']
        if node.op_type == 'Constant' and len(node.attribute) == 1 and value:
            tensor = onnx.TensorProto()
            tensor.CopyFrom(value[0].t)
            tensor.name = node.output[0]
            model.graph.initializer.append(tensor)
            moved += 1
        else:
            kept.append(node)
    del model.graph.node[:]
    model.graph.node.extend(kept)
    onnx.save(model, path)
    return moved


def graph_summary(path: str) -> Dict:
    """What a graph holds: its size, nodes and interface.

    Args:
        path (str): An ONNX file.

    Returns:
        dict: ``nodes`` (count), ``ops`` (op type -> count, most common
        first), ``bytes`` (file size), ``inputs`` and ``outputs`` (name ->
        shape, a symbolic axis as its name), ``unused_inputs`` (declared
        inputs that no node reads: a sign that the export turned them into
        constants) and ``opset``.
    """
    import onnx
    model = onnx.load(path, load_external_data=False)

    def shapes(values) -> Dict[str, List]:
        return {
            v.name: [d.dim_param or d.dim_value
                     for d in v.type.tensor_type.shape.dim]
            for v in values
        }

    read = set()
    for node in model.graph.node:
        read.update(node.input)
        for attr in node.attribute:
            # Subgraphs (If branches) read names of the outer graph.
            for sub in list(attr.g.node if attr.HasField('g') else []):
                read.update(sub.input)
    ops = Counter(node.op_type for node in model.graph.node)
    return dict(
        nodes=len(model.graph.node),
        ops=dict(ops.most_common()),
        bytes=osp.getsize(path),
        inputs=shapes(model.graph.input),
        outputs=shapes(model.graph.output),
        unused_inputs=[
            v.name for v in model.graph.input if v.name not in read
        ],
        opset=max(o.version for o in model.opset_import
                  if o.domain in ('', 'ai.onnx')))


def onnx_session(path: str, threads: Optional[int] = None):
    """An onnxruntime CPU session of a graph.

    Args:
        path (str): An ONNX file.
        threads (int, optional): Intra-op threads; None lets onnxruntime
            choose. Defaults to None.

    Returns:
        onnxruntime.InferenceSession: The session.
    """
    import onnxruntime as ort
    options = ort.SessionOptions()
    if threads:
        options.intra_op_num_threads = int(threads)
    # Idle threads sleep instead of spinning: timed beside PyTorch in
    # alternating rounds, spinning threads would take its cores.
    options.add_session_config_entry('session.intra_op.allow_spinning', '0')
    return ort.InferenceSession(
        path, options, providers=['CPUExecutionProvider'])


def run_graph(session, feeds: Mapping[str, Tensor]) -> Dict[str, np.ndarray]:
    """Run a session on tensors.

    Args:
        session (onnxruntime.InferenceSession): From :func:`onnx_session`.
        feeds (Mapping[str, Tensor]): Input name -> tensor (CPU).

    Returns:
        dict[str, np.ndarray]: Output name -> array.
    """
    names = [out.name for out in session.get_outputs()]
    arrays = {
        name: value.detach().cpu().numpy()
        for name, value in feeds.items()
    }
    return dict(zip(names, session.run(names, arrays)))


def logits_parity(reference: Tensor, logits: np.ndarray) -> Dict[str, float]:
    """How far a runtime's occupancy logits are from PyTorch's.

    Args:
        reference (Tensor): PyTorch's logits. Shape (B, K, X, Y, Z).
        logits (np.ndarray): The runtime's, same shape.

    Returns:
        dict[str, float]: ``max_abs_diff`` of the logits and
        ``argmax_agreement``, the share of voxels whose most likely class
        is the same (1.0 = all).
    """
    ref = reference.detach().cpu().numpy()
    if ref.shape != logits.shape:
        raise ValueError(f'logits of shape {logits.shape} against '
                         f'PyTorch\'s {ref.shape}')
    return dict(
        max_abs_diff=float(np.abs(ref - logits).max()),
        argmax_agreement=float(
            (ref.argmax(axis=1) == logits.argmax(axis=1)).mean()))
