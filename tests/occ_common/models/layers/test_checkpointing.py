"""checkpoint_if_grad recomputes only where a backward will need it."""
import torch

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
