"""The data preprocessor's image steps as a module of an exported graph.

``Det3DDataPreprocessor`` turns the pipeline's images into the network's
input: the channel swap (``bgr_to_rgb``), ``(x - mean) / std`` and a
bottom / right padding to ``pad_size_divisor``. An exported graph that
starts from the pipeline's images must do the same, with the same
numbers, so they are read from the model's own preprocessor.
"""
import torch
import torch.nn.functional as F
from torch import Tensor, nn


class GraphImagePreprocess(nn.Module):
    """Channel swap, normalisation and padding of multi-view images.

    Args:
        data_preprocessor (nn.Module): The model's
            ``Det3DDataPreprocessor`` (its ``mean``, ``std``,
            ``_channel_conversion``, ``pad_size_divisor``, ``pad_value``).
    """

    def __init__(self, data_preprocessor: nn.Module) -> None:
        super().__init__()
        self.swap = bool(getattr(data_preprocessor, '_channel_conversion',
                                 False))
        self.normalize = bool(
            getattr(data_preprocessor, '_enable_normalize', False))
        mean = getattr(data_preprocessor, 'mean', None)
        std = getattr(data_preprocessor, 'std', None)
        self.register_buffer(
            'mean',
            (mean if self.normalize else torch.zeros(3)).reshape(
                1, 1, 3, 1, 1).float().clone(),
            persistent=False)
        self.register_buffer(
            'std',
            (std if self.normalize else torch.ones(3)).reshape(
                1, 1, 3, 1, 1).float().clone(),
            persistent=False)
        self.divisor = int(getattr(data_preprocessor, 'pad_size_divisor', 1))
        self.pad_value = float(getattr(data_preprocessor, 'pad_value', 0))

    def forward(self, imgs: Tensor) -> Tensor:
        """Network input of the pipeline's images.

        Args:
            imgs (Tensor): Pixel values 0-255 in the pipeline's channel
                order. Shape (B, N, 3, H, W).

        Returns:
            Tensor: float32, padded to multiples of ``pad_size_divisor``.
            Shape (B, N, 3, H', W').
        """
        if imgs.dim() != 5 or imgs.shape[2] != 3:
            raise ValueError('GraphImagePreprocess expects (B, N, 3, H, W), '
                             f'got {tuple(imgs.shape)}')
        if self.swap:
            imgs = imgs.flip(2)
        imgs = (imgs.float() - self.mean) / self.std
        height, width = imgs.shape[-2:]
        pad_h = -height % self.divisor
        pad_w = -width % self.divisor
        if pad_h or pad_w:
            imgs = F.pad(imgs, (0, pad_w, 0, pad_h), value=self.pad_value)
        return imgs
