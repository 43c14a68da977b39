"""Float32 islands in mixed-precision training.

Under ``--amp`` mmengine runs the whole forward in ``torch.autocast``:
convolutions and matrix products (``matmul``, ``einsum``'s ``bmm``) return
float16 / bfloat16. That is what the networks want and what geometry must
not get: a LiDAR-to-image product forms ``u * d`` up to 1600 px x 50 m =
80,000, above float16's largest value 65,504, and bfloat16's 8-bit
mantissa moves a point at 50 m by up to 0.2 m. Functions decorated with
:func:`float32_math` (projection, depth binning, frustum, cylindrical
coordinates, BEV warp, the losses) run with autocast off and their
low-precision tensor arguments cast to float32, as mmcv 1.x's
``force_fp32`` did. Without autocast they run unchanged (no cast, no
context), so fp32 training and every fp32 test see the same code path.
"""
import contextlib
import functools
from typing import Any, Callable, Iterator

import torch

#: Autocast device types a float32 island switches off.
AUTOCAST_DEVICES = ('cuda', 'cpu')
#: Dtypes autocast produces; a float32 island casts them up.
LOW_PRECISION = (torch.float16, torch.bfloat16)


def autocast_active() -> bool:
    """Whether autocast is on for any device type of
    :data:`AUTOCAST_DEVICES`."""
    return any(torch.is_autocast_enabled(d) for d in AUTOCAST_DEVICES)


@contextlib.contextmanager
def autocast_disabled() -> Iterator[None]:
    """Switch autocast off for every device type it is on for."""
    with contextlib.ExitStack() as stack:
        for device in AUTOCAST_DEVICES:
            if torch.is_autocast_enabled(device):
                stack.enter_context(torch.autocast(device, enabled=False))
        yield


def to_float32(value: Any) -> Any:
    """``value`` with its float16 / bfloat16 tensors cast to float32,
    looking into lists, tuples and dicts; anything else unchanged."""
    if isinstance(value, torch.Tensor):
        return value.float() if value.dtype in LOW_PRECISION else value
    if isinstance(value, (list, tuple)):
        cast = [to_float32(v) for v in value]
        return type(value)(cast) if isinstance(value, list) else tuple(cast)
    if isinstance(value, dict):
        return {k: to_float32(v) for k, v in value.items()}
    return value


def float32_math(fn: Callable) -> Callable:
    """Decorator: under autocast, run ``fn`` in float32 with autocast off.

    Its float16 / bfloat16 tensor arguments are cast to float32 (gradients
    flow back through the cast in their own dtype); its outputs stay
    float32, and the next autocast op casts them down where it wants.
    Without autocast ``fn`` is called as is.
    """

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        if not autocast_active():
            return fn(*args, **kwargs)
        with autocast_disabled():
            return fn(*to_float32(args), **to_float32(kwargs))

    return wrapper
