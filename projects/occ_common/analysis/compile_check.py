"""Count what ``torch.compile`` makes of a model: graph breaks and
recompilations, on any device.

A graph break is a place where TorchDynamo stops its graph, runs Python
(and, on a GPU, launches the operators one by one) and starts a new graph;
a recompilation is a new graph for an input that the guards of the graphs
already compiled refuse (a new point count, say). Both are properties of
the code, not of the device, so they are counted on the CPU:

* :func:`explain_breaks` runs ``torch._dynamo.explain`` (an eager backend:
  nothing is compiled, a tiny model takes seconds) and gives each break's
  reason and the innermost frame of this project's code it came from;
* :func:`count_recompiles` compiles a function with a backend that only
  counts graphs and calls it on several inputs in turn; every graph made
  after the first call is a recompilation, with the guard that failed.

:func:`phase_call` is the call that is counted: a prediction
(``model(inputs, data_samples, mode='predict')`` without autograd) or a
training step's forward (``mode='loss'`` and ``parse_losses``: the graph
AOTAutograd differentiates, the backward adds no Dynamo graph break), both
from the data preprocessor's output, as ``tools/analysis_tools/count_ops.py``
counts from the collated batch. Run under Dynamo the model takes its GPU
code path on every device (``torch.compiler.is_compiling``: see
:mod:`projects.occ_common.utils.device_path`).
"""
import contextlib
import logging
import os.path as osp
from typing import Callable, Dict, Iterator, List, NamedTuple, Sequence

import torch
from torch import nn

#: The directory this project's code lives in (``projects/``' parent).
_ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
PHASES = ('predict', 'train')


class GraphBreak(NamedTuple):
    """One graph break: why, and where in the code.

    Attributes:
        reason (str): Dynamo's reason, its first line (e.g. ``'Dynamic
            shape operator'``, ``'Unsupported Tensor.item() call'``).
        location (str): ``path:line`` of the innermost frame in this
            repository (relative to its root), else the innermost frame.
        function (str): The function of that frame.
        code (str): Its source line.
    """
    reason: str
    location: str
    function: str
    code: str


class BreakReport(NamedTuple):
    """What ``torch._dynamo.explain`` found.

    Attributes:
        graphs (int): Graphs traced.
        breaks (list[GraphBreak]): In the order they happened.
        ops (int): Operators in all graphs.
    """
    graphs: int
    breaks: List[GraphBreak]
    ops: int

    def by_site(self) -> List[Dict]:
        """Breaks grouped by (reason, location), most frequent first.

        Returns:
            list[dict]: ``reason``, ``location``, ``function``, ``code``,
            ``count``.
        """
        counts: Dict[GraphBreak, int] = {}
        for item in self.breaks:
            counts[item] = counts.get(item, 0) + 1
        return [
            dict(item._asdict(), count=n)
            for item, n in sorted(counts.items(), key=lambda kv: -kv[1])
        ]


def _break_site(reason) -> GraphBreak:
    """The :class:`GraphBreak` of one of Dynamo's ``GraphCompileReason``."""
    stack = list(reason.user_stack or [])
    ours = [f for f in stack if osp.abspath(f.filename).startswith(_ROOT)
            and '/site-packages/' not in f.filename]
    frame = (ours or stack or [None])[-1]
    text = (reason.reason or '').strip().splitlines()
    summary = text[0] if text else 'unknown'
    if frame is None:
        return GraphBreak(summary, '?', '?', '')
    path = osp.abspath(frame.filename)
    if path.startswith(_ROOT + osp.sep):
        path = osp.relpath(path, _ROOT)
    return GraphBreak(summary, f'{path}:{frame.lineno}', frame.name,
                      (frame.line or '').strip())


def explain_breaks(fn: Callable, *args, **kwargs) -> BreakReport:
    """Trace ``fn(*args, **kwargs)`` with Dynamo and report its breaks.

    Dynamo's caches are reset before and after, so that earlier
    compilations neither hide nor add breaks.

    Args:
        fn (Callable): What to trace (run once, eagerly, by Dynamo).
        *args, **kwargs: Its arguments.

    Returns:
        BreakReport: Graphs, breaks, operators.
    """
    import torch._dynamo as dynamo
    dynamo.reset()
    try:
        out = dynamo.explain(fn)(*args, **kwargs)
    finally:
        dynamo.reset()
    return BreakReport(out.graph_count,
                       [_break_site(r) for r in out.break_reasons],
                       out.op_count)


def parse_loss(model: nn.Module, losses: Dict) -> torch.Tensor:
    """The total loss mmengine's ``train_step`` back-propagates."""
    loss, _ = model.parse_losses(losses)
    return loss


def phase_call(model: nn.Module, phase: str) -> Callable[[dict], object]:
    """The counted call of ``phase`` on a preprocessed batch.

    Puts the model in eval mode for ``'predict'`` and train mode for
    ``'train'``.

    Args:
        model (nn.Module): An mmengine ``BaseModel``.
        phase (str): ``'predict'`` (``mode='predict'`` under
            ``torch.no_grad``) or ``'train'`` (``mode='loss'``, then the
            total loss of ``parse_losses``).

    Returns:
        Callable: Takes the data preprocessor's output
        (``dict(inputs, data_samples)``).
    """
    if phase not in PHASES:
        raise ValueError(f'phase must be one of {PHASES}, got {phase!r}')
    if phase == 'predict':
        model.eval()

        def predict(data: dict):
            with torch.no_grad():
                return model(data['inputs'], data['data_samples'],
                             mode='predict')

        return predict
    model.train()

    def train(data: dict):
        return parse_loss(
            model, model(data['inputs'], data['data_samples'], mode='loss'))

    return train


class _CountingBackend:
    """A ``torch.compile`` backend that runs each graph as traced and
    counts them."""

    def __init__(self) -> None:
        self.graphs = 0

    def __call__(self, gm: torch.fx.GraphModule, example_inputs):
        self.graphs += 1
        return gm.forward


class _RecompileLog(logging.Handler):
    """Collects Dynamo's ``recompiles`` log records (the failed guards)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.messages: List[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if 'Recompiling' in message or 'guard failure' in message:
            self.messages.append(message)


@contextlib.contextmanager
def recompile_log() -> Iterator[_RecompileLog]:
    """Collect the reason of every recompilation made inside the block."""
    handler = _RecompileLog()
    logger = logging.getLogger('torch._dynamo')
    torch._logging.set_logs(recompiles=True)
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        torch._logging.set_logs()


class RecompileReport(NamedTuple):
    """Graphs compiled per call, and why any call after the first
    compiled.

    Attributes:
        graphs_per_call (list[int]): New graphs of each call.
        reasons (list[str]): Dynamo's guard failures of the
            recompilations.
    """
    graphs_per_call: List[int]
    reasons: List[str]

    @property
    def recompiles(self) -> int:
        """int: Graphs compiled after the first call."""
        return sum(self.graphs_per_call[1:])


def count_recompiles(fn: Callable, inputs: Sequence,
                     dynamic=None) -> RecompileReport:
    """Compile ``fn`` (a counting backend), call it on each input in turn.

    Args:
        fn (Callable): Takes one input.
        inputs (Sequence): The inputs, e.g. batches of different point
            counts.
        dynamic (bool, optional): ``torch.compile``'s ``dynamic``.
            Defaults to None (static until a size changes, Dynamo's
            default; dims marked with ``torch._dynamo.mark_dynamic`` are
            dynamic from the start).

    Returns:
        RecompileReport: New graphs per call; the reasons.
    """
    import torch._dynamo as dynamo
    backend = _CountingBackend()
    dynamo.reset()
    compiled = torch.compile(fn, backend=backend, dynamic=dynamic)
    per_call = []
    try:
        with recompile_log() as log:
            for item in inputs:
                before = backend.graphs
                compiled(item)
                per_call.append(backend.graphs - before)
    finally:
        dynamo.reset()
    return RecompileReport(per_call, log.messages)
