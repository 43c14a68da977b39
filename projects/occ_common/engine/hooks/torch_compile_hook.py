"""``compile=True`` for the whole run: prediction compiled too, and point
clouds of any size through one compiled graph.

mmengine's Runner reads the config's ``compile`` (True, or the keyword
arguments of ``torch.compile``) and compiles ``model.train_step`` when
training starts; validation and testing stay eager. This hook compiles
``val_step`` and ``test_step`` with the same options, when their loops
start, so ``tools/test.py CONFIG CKPT --cfg-options compile=True`` runs
the compiled prediction that the GPU benchmarks time.

Every sample's LiDAR cloud has its own number of points. Dynamo
specialises a graph to the sizes of its first inputs and compiles it again
for the next size it sees (then with that size dynamic); the hook marks
the point count of every cloud dynamic before each step instead
(``torch._dynamo.maybe_mark_dynamic``: it cannot be called inside the
compiled step), so the first graph already takes any count. Images, grids
and labels keep their static shapes.

The data preprocessor runs eagerly (``torch.compiler.disable``, one graph
break at the start of each step): mmdet3d's ``Det3DDataPreprocessor``
writes ``batch_input_shape`` and ``pad_shape`` with mmengine's
``set_metainfo``, which deep-copies the samples' numpy metainfo, and
Dynamo cannot trace that copy (a hard error, not a break: found
2026-11-28 by ``tools/train.py ... compile.backend=eager``). The model's
forward after it is compiled.

Without ``compile`` in the config the hook does nothing.
"""
from typing import Optional

import torch
from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook


def mark_dynamic_points(data) -> int:
    """Mark the point count (dim 0) of every cloud of a batch dynamic.

    Args:
        data (dict | list[dict]): A collated batch or the data
            preprocessor's output (``inputs['points']``: a list of (P_b, C)
            tensors), or a list of them (test-time augmentation).

    Returns:
        int: Clouds marked (0 for a batch without points).
    """
    if isinstance(data, (list, tuple)):
        return sum(mark_dynamic_points(item) for item in data)
    inputs = data.get('inputs') if isinstance(data, dict) else None
    points = inputs.get('points') if isinstance(inputs, dict) else None
    if points is None:
        return 0
    clouds = [points] if isinstance(points, torch.Tensor) else list(points)
    for cloud in clouds:
        torch._dynamo.maybe_mark_dynamic(cloud, 0)
    return len(clouds)


def compile_options(cfg) -> Optional[dict]:
    """The ``torch.compile`` keyword arguments a config's ``compile`` asks
    for (mmengine's reading), or None when it asks for none.

    Args:
        cfg (Config | dict): With an optional ``compile``: a bool or a
            dict.

    Returns:
        dict | None: Keyword arguments of ``torch.compile``.
    """
    value = cfg.get('compile', None)
    if value is None or value is False:
        return None
    if value is True:
        return {}
    if not isinstance(value, dict):
        raise TypeError(f'compile must be a bool or a dict of torch.compile '
                        f'arguments, got {type(value).__name__}')
    return dict(value)


@HOOKS.register_module()
class TorchCompileHook(Hook):
    """Compile ``val_step`` / ``test_step`` and mark point counts dynamic
    when the config sets ``compile`` (see the module docstring).

    Args:
        mark_dynamic (bool): Mark every cloud's point count dynamic before
            each step. Defaults to True.
    """
    priority = 'LOW'

    def __init__(self, mark_dynamic: bool = True) -> None:
        self.mark_dynamic = bool(mark_dynamic)
        self._compiled = set()

    def _options(self, runner) -> Optional[dict]:
        return compile_options(runner.cfg)

    def _compile(self, runner, target: str) -> None:
        options = self._options(runner)
        if options is None or target in self._compiled:
            return
        setattr(runner.model, target,
                torch.compile(getattr(runner.model, target), **options))
        self._compiled.add(target)
        runner.logger.info(f'TorchCompileHook: {target} compiled with '
                           f'{options or "the default options"}')

    def _mark(self, runner, data_batch) -> None:
        if self.mark_dynamic and data_batch is not None and \
                self._options(runner) is not None:
            mark_dynamic_points(data_batch)

    def before_run(self, runner) -> None:
        """Run the data preprocessor eagerly when compiling (see the
        module docstring); mmengine compiles ``train_step`` after this, on
        its first call."""
        if self._options(runner) is None:
            return
        model = getattr(runner.model, 'module', runner.model)
        preprocessor = getattr(model, 'data_preprocessor', None)
        if preprocessor is not None and \
                not getattr(preprocessor, '_occ_eager', False):
            preprocessor.forward = torch.compiler.disable(
                preprocessor.forward)
            preprocessor._occ_eager = True

    def before_val(self, runner) -> None:
        """Compile ``val_step``, once."""
        self._compile(runner, 'val_step')

    def before_test(self, runner) -> None:
        """Compile ``test_step``, once."""
        self._compile(runner, 'test_step')

    def before_train_iter(self, runner, batch_idx: int,
                          data_batch=None) -> None:
        """Mark the batch's point counts dynamic."""
        self._mark(runner, data_batch)

    def before_val_iter(self, runner, batch_idx: int,
                        data_batch=None) -> None:
        """Mark the batch's point counts dynamic."""
        self._mark(runner, data_batch)

    def before_test_iter(self, runner, batch_idx: int,
                         data_batch=None) -> None:
        """Mark the batch's point counts dynamic."""
        self._mark(runner, data_batch)
