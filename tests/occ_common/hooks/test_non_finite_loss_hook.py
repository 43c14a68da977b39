"""NaN / inf losses stop training before a checkpoint is written."""
import os.path as osp
import subprocess
import sys
import types

import pytest
import torch
from mmengine.logging import MessageHub

from projects.occ_common.hooks import NonFiniteLossError, NonFiniteLossHook
from projects.occ_common.hooks.non_finite_loss_hook import non_finite_terms

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


def _runner(iteration, epoch_based=True, last_ckpt=None):
    """The runner attributes the hook reads (iteration is 0-based)."""
    hub = MessageHub.get_instance(f'nan_hook_{iteration}_{last_ckpt}')
    if last_ckpt:
        hub.update_info('last_ckpt', last_ckpt)
    loop = types.SimpleNamespace(max_epochs=3) if epoch_based else object()
    return types.SimpleNamespace(
        iter=iteration, epoch=1, train_loop=loop, message_hub=hub)


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


def test_hook_names_iteration_epoch_term_and_last_checkpoint():
    """0-based runner.iter 5 is iteration 6 of the log; epoch 1 -> 2."""
    hook = NonFiniteLossHook()
    runner = _runner(5, last_ckpt='work/iter_5.pth')
    outputs = dict(loss=torch.tensor(float('nan')),
                   loss_ce=torch.tensor(float('nan')),
                   loss_aux=torch.tensor(0.25))
    with pytest.raises(NonFiniteLossError) as info:
        hook.after_train_iter(runner, batch_idx=1, outputs=outputs)
    message = str(info.value)
    assert ('iteration 6 (epoch 2, batch 2): loss_ce=nan, loss=nan.'
            in message)
    assert 'loss_aux' not in message
    assert 'the last checkpoint written is work/iter_5.pth' in message


def test_iteration_based_runs_and_intervals():
    """No epoch in the message of an iter-based loop; interval skips."""
    outputs = dict(loss=torch.tensor(float('inf')))
    with pytest.raises(NonFiniteLossError,
                       match=r'iteration 4: loss=inf\. .*no checkpoint'):
        NonFiniteLossHook().after_train_iter(
            _runner(3, epoch_based=False), 0, outputs=outputs)
    # interval 3 checks after iterations 3, 6, ... (runner.iter 2, 5).
    NonFiniteLossHook(interval=3).after_train_iter(
        _runner(3), 0, outputs=outputs)
    NonFiniteLossHook().after_train_iter(
        _runner(3), 0, outputs=dict(loss=torch.tensor(0.1)))
    with pytest.raises(ValueError, match='interval >= 1'):
        NonFiniteLossHook(interval=0)


@pytest.mark.slow
def test_train_stops_at_the_nan_iteration_keeping_the_previous_ckpt(
        tmp_path):
    """tools/train.py, a checkpoint after every iteration, NaN at 6.

    8 samples / batch 2 = 4 iterations per epoch: iteration 6 is epoch 2,
    batch 2. CheckpointHook saves in after_train_iter after this hook, so
    iter_5.pth is the last checkpoint and iter_6.pth never appears.
    """
    work_dir = str(tmp_path / 'work')
    proc = subprocess.run(
        [sys.executable, osp.join(ROOT, 'tools', 'train.py'), CONFIG,
         '--work-dir', work_dir, '--cfg-options', 'model.nan_at_iter=6',
         'default_hooks.checkpoint.by_epoch=False',
         'train_cfg.val_interval=100'],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0
    assert ('NonFiniteLossError: Non-finite loss at iteration 6 (epoch 2, '
            'batch 2): loss_ce=nan, loss=nan.') in proc.stderr
    assert osp.isfile(osp.join(work_dir, 'iter_5.pth'))
    assert not osp.exists(osp.join(work_dir, 'iter_6.pth'))
    with open(osp.join(work_dir, 'last_checkpoint')) as f:
        assert f.read().strip().endswith('iter_5.pth')
