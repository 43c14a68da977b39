"""checkpoint_if_grad recomputes only where a backward will need it."""
import torch
from torch.utils.checkpoint import checkpoint

from projects.occ_common.models.layers.checkpointing import checkpoint_if_grad


def test_recomputes_only_with_a_graph():
    """``run = x -> (x * w).sin()`` is called twice (forward, then again
    in the backward) when enabled and ``x`` requires grad, once otherwise;
    values and the gradient d/dx = w cos(x w) are the same."""
    calls = []
    w = torch.tensor([2.0, -1.0], dtype=torch.float64)

    def run(x, scale):
        calls.append(scale)
        return (x * w * scale).sin()

    x0 = torch.tensor([0.3, 0.7], dtype=torch.float64)
    grads = []
    for enabled, expected_calls in ((False, 1), (True, 2)):
        calls.clear()
        x = x0.clone().requires_grad_()
        out = checkpoint_if_grad(enabled, run, x, 1.0)
        out.sum().backward()
        assert len(calls) == expected_calls
        torch.testing.assert_close(out, (x0 * w).sin())
        grads.append(x.grad)
    assert torch.equal(grads[0], grads[1])
    torch.testing.assert_close(grads[0], w * (x0 * w).cos())
    for grad_mode, x in ((False, x0.clone().requires_grad_()), (True, x0)):
        calls.clear()
        with torch.set_grad_enabled(grad_mode):
            checkpoint_if_grad(True, run, x, 1.0)
        assert len(calls) == 1


def _conv_bn(momentum):
    torch.manual_seed(0)
    return torch.nn.Sequential(
        torch.nn.Conv2d(2, 3, 3, padding=1),
        torch.nn.BatchNorm2d(3, momentum=momentum),
        torch.nn.ReLU()).double().train()


def _step(block, x, **checkpoint_kwargs):
    """One forward + backward of ``block`` (plain when no kwargs); returns
    the output, the parameter gradients and the buffers after it."""
    block.zero_grad()
    if checkpoint_kwargs:
        out = checkpoint_if_grad(True, block, x, **checkpoint_kwargs)
    else:
        out = block(x)
    (out * torch.arange(out.numel(), dtype=out.dtype).view_as(out)
     ).sum().backward()
    grads = [p.grad.clone() for p in block.parameters()]
    return out.detach(), grads, [b.clone() for b in block.buffers()]


def test_training_batchnorm_statistics_update_once():
    """A conv-BN-ReLU block with training BatchNorm, fed an input without
    gradient (the output of a frozen stage): with ``module`` given it is
    still recomputed (its parameters need gradients), and output,
    parameter gradients and running mean / variance / batch count equal
    a plain forward's, for an exponential (0.1) and a cumulative (None)
    momentum. Plain ``torch.utils.checkpoint`` runs the BatchNorm twice:
    the batch count reads 2 instead of 1 and, with momentum 0.1, the running
    mean moves twice (0.9**2 instead of 0.9 of the initial 0 weighting)."""
    x = torch.randn(2, 2, 5, 4, dtype=torch.float64)
    for momentum in (0.1, None):
        plain = _step(_conv_bn(momentum), x)
        block = _conv_bn(momentum)
        calls = []
        block.register_forward_pre_hook(lambda *a: calls.append(1))
        recomputed = _step(block, x, module=block)
        assert len(calls) == 2
        for a, b in zip(plain[1] + plain[2], recomputed[1] + recomputed[2]):
            torch.testing.assert_close(a, b, rtol=0, atol=1e-15)
        torch.testing.assert_close(plain[0], recomputed[0], rtol=0, atol=0)
        assert int(recomputed[2][2]) == 1

        naive = _conv_bn(momentum)
        out = checkpoint(naive, x, use_reentrant=False)
        out.sum().backward()
        assert int(naive[1].num_batches_tracked) == 2
        if momentum is not None:  # a cumulative mean of one batch twice
            assert not torch.allclose(naive[1].running_mean, plain[2][0])


def test_module_parameters_count_as_inputs():
    """Without ``module`` an input without gradient means no recomputation
    (one call), with it the block's trainable parameters make one (two
    calls); frozen parameters and ``no_grad`` make none."""
    block = _conv_bn(0.1)
    x = torch.randn(1, 2, 3, 3, dtype=torch.float64)
    calls = []
    block.register_forward_pre_hook(lambda *a: calls.append(1))
    for kwargs, grad_mode, frozen, expected in (
            (dict(), True, False, 1), (dict(module=block), True, False, 2),
            (dict(module=block), False, False, 1),
            (dict(module=block), True, True, 1)):
        calls.clear()
        for p in block.parameters():
            p.requires_grad_(not frozen)
        with torch.set_grad_enabled(grad_mode):
            out = checkpoint_if_grad(True, block, x, **kwargs)
        if out.requires_grad:
            out.sum().backward()
        assert len(calls) == expected, (kwargs, grad_mode, frozen)
