"""Image backbones shared by the occupancy models."""
from .recomputed_resnet import RecomputedResNet

__all__ = ['RecomputedResNet']
