"""Tests of TorchCompileHook: compile=True reaches val/test steps, and
point counts are marked dynamic."""
from types import SimpleNamespace

import pytest
import torch
from mmengine.config import Config
from mmengine.logging import MMLogger

from projects.occ_common.engine.hooks import TorchCompileHook
from projects.occ_common.engine.hooks.torch_compile_hook import (
    compile_options, mark_dynamic_points)


def test_compile_options_read_like_mmengine():
    assert compile_options(Config(dict())) is None
    assert compile_options(Config(dict(compile=False))) is None
    assert compile_options(Config(dict(compile=True))) == {}
    assert compile_options(Config(dict(compile=dict(
        backend='eager')))) == dict(backend='eager')
    with pytest.raises(TypeError, match='compile must be a bool'):
        compile_options(Config(dict(compile='yes')))


def test_points_marked_dynamic_in_batches_and_lists():
    """Two clouds in a batch, one in a second (TTA list): 3 marked, dim 0
    each; a batch without points marks none."""
    clouds = [torch.zeros(5, 4), torch.zeros(7, 4)]
    extra = torch.zeros(3, 4)
    count = mark_dynamic_points([dict(inputs=dict(points=clouds)),
                                 dict(inputs=dict(points=[extra]))])
    assert count == 3
    assert all(c._dynamo_weak_dynamic_indices == {0}
               for c in clouds + [extra])
    assert mark_dynamic_points(dict(inputs=dict(imgs=torch.zeros(1)))) == 0


class _Model(torch.nn.Module):

    def test_step(self, data):
        return data * 2

    def val_step(self, data):
        return data + 1


def _runner(compile_value):
    cfg = Config(dict() if compile_value is None else dict(
        compile=compile_value))
    return SimpleNamespace(cfg=cfg, model=_Model(),
                           logger=MMLogger.get_instance('compile_hook'))


def test_hook_compiles_test_and_val_steps_once_when_asked():
    """compile=dict(backend=a graph counter): test_step and val_step run
    through torch.compile (one graph each, same values: 2 * 3 = 6, 3 + 1
    = 4), compiled once however many loops start; without ``compile``
    nothing changes."""
    graphs = []

    def backend(gm, example_inputs):
        graphs.append(gm)
        return gm.forward

    torch._dynamo.reset()
    hook, runner = TorchCompileHook(), _runner(dict(backend=backend))
    hook.before_test(runner)
    compiled = runner.model.test_step
    hook.before_test(runner)
    hook.before_val(runner)
    assert runner.model.test_step is compiled
    assert runner.model.test_step(torch.tensor(3.0)).item() == 6.0
    assert runner.model.val_step(torch.tensor(3.0)).item() == 4.0
    assert len(graphs) == 2
    plain = _runner(None)
    step = plain.model.test_step
    TorchCompileHook().before_test(plain)
    assert plain.model.test_step == step
    points = [torch.zeros(5, 4)]
    TorchCompileHook().before_test_iter(plain, 0,
                                        dict(inputs=dict(points=points)))
    assert not hasattr(points[0], '_dynamo_weak_dynamic_indices')


def test_data_preprocessor_runs_eagerly_only_when_compiling():
    """mmdet3d's preprocessor deep-copies numpy metainfo, which Dynamo
    cannot trace: with ``compile`` the hook makes its forward an eager
    island (traced as a break, not into the graph; values unchanged: 3 + 1
    = 4), once; without ``compile`` the forward is left alone."""
    from projects.occ_common.analysis.compile_check import explain_breaks

    class Preprocessor(torch.nn.Module):

        def forward(self, x):
            return x + 1

    runner = _runner(dict(backend='eager'))
    runner.model.data_preprocessor = Preprocessor()
    TorchCompileHook().before_run(runner)
    TorchCompileHook().before_run(runner)
    pre = runner.model.data_preprocessor
    assert pre(torch.tensor(3.0)).item() == 4.0

    def step(x):
        return pre(x * 2) * 3

    assert len(explain_breaks(step, torch.ones(2)).breaks) == 1
    plain = _runner(None)
    plain.model.data_preprocessor = Preprocessor()
    TorchCompileHook().before_run(plain)
    pre = plain.model.data_preprocessor
    assert not getattr(pre, '_occ_eager', False)
    assert len(explain_breaks(step, torch.ones(2)).breaks) == 0
