"""Choice of the sparse convolution backend: spconv or pure PyTorch.

spconv 2.x runs fast fused kernels on CUDA, but a CPU-only wheel has no
backward (its backward asserts CUDA) and may be missing altogether. The
``'torch'`` backend (:mod:`.torch_backend`) runs forward and backward on
any device. ``'auto'`` decides per call from the features' device.
"""
from typing import Optional, Protocol, Tuple

from torch import Tensor

BACKENDS = ('auto', 'spconv', 'torch')

try:
    import spconv.pytorch  # noqa: F401
    from spconv.cppconstants import CPU_ONLY_BUILD as _SPCONV_CPU_ONLY
    _SPCONV_ERROR = None
except ImportError as error:  # the torch backend still works without it
    _SPCONV_CPU_ONLY = True
    _SPCONV_ERROR = error


def spconv_available() -> bool:
    """Whether spconv (any build) can be imported.

    Returns:
        bool: True if ``spconv.pytorch`` imported.
    """
    return _SPCONV_ERROR is None


def spconv_supports_cuda() -> bool:
    """Whether the installed spconv has CUDA kernels.

    Returns:
        bool: False for a missing spconv or a CPU-only wheel.
    """
    return spconv_available() and not _SPCONV_CPU_ONLY


def check_backend(backend: str) -> str:
    """Validate a backend name.

    Args:
        backend (str): One of :data:`BACKENDS`.

    Returns:
        str: The same name.
    """
    if backend not in BACKENDS:
        raise ValueError(
            f'sparse backend must be one of {BACKENDS}, got {backend!r}')
    return backend


def resolve_backend(backend: str, features: Tensor) -> str:
    """Pick the backend that runs a layer on these features.

    ``'auto'`` means spconv for CUDA tensors and the torch backend
    otherwise. It also falls back to torch on CUDA when spconv is missing
    or CPU-only, since such a build cannot run CUDA tensors at all.

    Args:
        backend (str): ``'auto'``, ``'spconv'`` or ``'torch'``.
        features (Tensor): The layer's input features. Shape (N, C).

    Returns:
        str: ``'spconv'`` or ``'torch'``.
    """
    check_backend(backend)
    if backend == 'auto':
        if features.is_cuda and spconv_supports_cuda():
            return 'spconv'
        return 'torch'
    if backend == 'spconv':
        if not spconv_available():
            raise ImportError(
                "sparse backend 'spconv' was requested but spconv cannot be "
                f"imported ({_SPCONV_ERROR}); install spconv-cuXXX or use "
                "backend='torch'")
        if features.is_cuda and not spconv_supports_cuda():
            raise RuntimeError(
                "sparse backend 'spconv' got CUDA features but the installed "
                "spconv is a CPU-only build; install spconv-cuXXX or use "
                "backend='torch'")
    return backend


class SparseConvLayer(Protocol):
    """What a backend reads from a sparse convolution layer.

    :class:`~.sparse_conv.SparseConvBase` provides it; the backends depend
    on this description rather than on the layer class, so the layer module
    imports the backends and nothing imports it back.
    """

    in_channels: int
    out_channels: int
    kernel_size: Tuple[int, int, int]
    stride: Tuple[int, int, int]
    padding: Tuple[int, int, int]
    dilation: Tuple[int, int, int]
    indice_key: Optional[str]
    subm: bool
    inverse: bool
    training: bool
    weight: Tensor
    bias: Optional[Tensor]

    @property
    def conv1x1(self) -> bool:
        """bool: Kernel volume 1 at stride 1, a per-site linear map."""

    @property
    def geometry(self) -> tuple:
        """tuple: Hashable description of everything but the parameters."""
