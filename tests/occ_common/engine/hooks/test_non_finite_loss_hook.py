"""Divergence stops training before a checkpoint is written, and the
last good checkpoint is kept and named."""
import os
import os.path as osp
import types

import pytest
import torch
from mmengine.logging import MessageHub

from projects.occ_common.engine.hooks import (NonFiniteLossError,
                                              NonFiniteLossHook)
from projects.occ_common.engine.hooks.non_finite_loss_hook import (
    non_finite_tensors, non_finite_terms)
from projects.occ_common.testing.tool_logs import REPO_ROOT as ROOT
from projects.occ_common.testing.tool_logs import run_tool

CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _runner(iteration, epoch_based=True, work_dir='/nonexistent',
            grad_norm=None, wrapper='OptimWrapper'):
    """The runner attributes the hook reads (iteration is 0-based)."""
    hub = MessageHub.get_instance(
        f'nan_hook_{iteration}_{work_dir}_{grad_norm}_{wrapper}')
    if grad_norm is not None:
        hub.update_scalar('train/grad_norm', grad_norm)
    loop = types.SimpleNamespace(max_epochs=3) if epoch_based else object()
    return types.SimpleNamespace(
        iter=iteration, epoch=1, train_loop=loop, message_hub=hub,
        work_dir=str(work_dir), optim_wrapper=type(wrapper, (), {})())


def test_non_finite_terms_lists_the_bad_loss_terms_total_last():
    """Only names with 'loss' count; tensors report the first bad value."""
    outputs = dict(
        loss=torch.tensor(float('nan')),
        loss_ce=torch.tensor([1.0, float('inf'), float('nan')]),
        loss_lovasz=torch.tensor(0.5),
        acc=torch.tensor(float('nan')),
        loss_count=torch.tensor(3))
    bad = non_finite_terms(outputs)
    assert list(bad) == ['loss_ce', 'loss']
    assert bad['loss_ce'] == float('inf')
    assert non_finite_terms({}) == {} and non_finite_terms(None) == {}


def test_checking_leaves_the_graph_intact():
    """The check detaches a copy: backward still gives d(2w)/dw = 2."""
    weight = torch.tensor(3.0, requires_grad=True)
    loss = 2 * weight
    assert non_finite_terms(dict(loss=loss)) == {}
    loss.backward()
    assert weight.grad.item() == 2.0


def test_hook_names_iteration_epoch_term_and_last_checkpoint(tmp_path):
    """0-based runner.iter 5 is iteration 6 of the log; epoch 1 -> 2."""
    hook = NonFiniteLossHook()
    (tmp_path / 'iter_5.pth').write_bytes(b'x')
    (tmp_path / 'last_checkpoint').write_text(str(tmp_path / 'iter_5.pth'))
    runner = _runner(5, work_dir=tmp_path)
    outputs = dict(loss=torch.tensor(float('nan')),
                   loss_ce=torch.tensor(float('nan')),
                   loss_aux=torch.tensor(0.25))
    with pytest.raises(NonFiniteLossError) as info:
        hook.after_train_iter(runner, batch_idx=1, outputs=outputs)
    message = str(info.value)
    assert ('iteration 6 (epoch 2, batch 2): loss_ce=nan, loss=nan.'
            in message)
    assert 'loss_aux' not in message
    assert (f'the last good checkpoint, {tmp_path}/iter_5.pth, is kept: '
            'resume from it with --resume') in message


def test_iteration_based_runs_and_intervals():
    """No epoch in the message of an iter-based loop; interval skips."""
    outputs = dict(loss=torch.tensor(float('inf')))
    with pytest.raises(NonFiniteLossError,
                       match=r'iteration 4: loss=inf\. .*no checkpoint was '
                       'written before'):
        NonFiniteLossHook().after_train_iter(
            _runner(3, epoch_based=False), 0, outputs=outputs)
    # interval 3 checks after iterations 3, 6, ... (runner.iter 2, 5).
    NonFiniteLossHook(interval=3).after_train_iter(
        _runner(3), 0, outputs=outputs)
    NonFiniteLossHook().after_train_iter(
        _runner(3), 0, outputs=dict(loss=torch.tensor(0.1)))
    with pytest.raises(ValueError, match='interval >= 1'):
        NonFiniteLossHook(interval=0)


def test_infinite_gradient_norm_stops_but_not_under_amp():
    """A logged grad_norm of inf is a bad term; AmpOptimWrapper's loss
    scaler expects (and skips) such steps."""
    outputs = dict(loss=torch.tensor(0.5))
    with pytest.raises(NonFiniteLossError, match='grad_norm=inf'):
        NonFiniteLossHook().after_train_iter(
            _runner(3, grad_norm=float('inf')), 0, outputs=outputs)
    NonFiniteLossHook().after_train_iter(
        _runner(3, grad_norm=float('inf'), wrapper='AmpOptimWrapper'), 0,
        outputs=outputs)
    NonFiniteLossHook().after_train_iter(
        _runner(3, grad_norm=2.0), 0, outputs=outputs)


def test_non_finite_weights_are_refused_before_saving():
    """state_dict and optimiser state: every bad tensor is named."""
    checkpoint = dict(
        state_dict=dict(w=torch.tensor([1.0, float('nan'), float('inf')]),
                        n=torch.tensor([3])),
        optimizer=dict(state={0: dict(momentum_buffer=torch.tensor(
            [float('-inf')]))}))
    assert non_finite_tensors(checkpoint) == [
        'state_dict.w (2 of 3 values)',
        'optimizer.state.0.momentum_buffer (1 of 1 values)'
    ]
    with pytest.raises(NonFiniteLossError,
                       match=r'Non-finite weights after iteration 4 '
                       r'\(epoch 2\).*state_dict.w \(2 of 3 values\), '
                       'optimizer'):
        NonFiniteLossHook().before_save_checkpoint(
            _runner(3), dict(checkpoint, meta=dict(epoch=2, iter=4)))
    NonFiniteLossHook().before_save_checkpoint(
        _runner(3), dict(state_dict=dict(w=torch.ones(2))))


def _train(work_dir, *options):
    """tools/train.py on the toy config without validation."""
    return run_tool('tools/train.py', CONFIG, '--work-dir', work_dir,
                    '--cfg-options', 'train_cfg.val_interval=100', *options,
                    timeout=300)


@pytest.mark.slow
def test_train_stops_at_the_nan_iteration_keeping_the_previous_ckpt(
        tmp_path):
    """tools/train.py, a checkpoint after every iteration, NaN at 6.

    8 samples / batch 2 = 4 iterations per epoch: iteration 6 is epoch 2,
    batch 2. CheckpointHook saves in after_train_iter after this hook, so
    iter_5.pth is the last checkpoint and iter_6.pth never appears.
    """
    work_dir = str(tmp_path / 'work')
    proc = _train(work_dir, 'model.nan_at_iter=6',
                  'default_hooks.checkpoint.by_epoch=False')
    assert proc.returncode != 0
    assert ('NonFiniteLossError: Non-finite loss at iteration 6 (epoch 2, '
            'batch 2): loss_ce=nan, loss=nan.') in proc.stderr
    assert osp.isfile(osp.join(work_dir, 'iter_5.pth'))
    assert not osp.exists(osp.join(work_dir, 'iter_6.pth'))
    with open(osp.join(work_dir, 'last_checkpoint')) as f:
        assert f.read().strip().endswith('iter_5.pth')


@pytest.mark.slow
def test_exploded_weights_are_never_saved_and_the_good_one_is_kept(
        tmp_path):
    """Iteration 8 (the last of epoch 2) explodes the weights while its
    loss is finite; max_keep_ckpts=1.

    mmengine's CheckpointHook would delete epoch_1.pth and save the
    exploded epoch_2.pth. Here the save is refused before anything is
    written or deleted, naming the bad tensors and the kept epoch_1.pth.
    """
    work_dir = str(tmp_path / 'work')
    proc = _train(work_dir, 'model.explode_at_iter=8',
                  'default_hooks.checkpoint.max_keep_ckpts=1')
    assert proc.returncode != 0
    ckpt = osp.join(work_dir, 'epoch_1.pth')
    assert ('NonFiniteLossError: Non-finite weights after iteration 8 '
            '(epoch 2), found before saving a checkpoint: state_dict.'
            'classifier.weight') in proc.stderr
    assert (f'the last good checkpoint, {ckpt}, is kept: resume from it'
            in proc.stderr)
    assert sorted(f for f in os.listdir(work_dir) if f.endswith('.pth')) \
        == ['epoch_1.pth']
