"""Image backbones shared by the occupancy models."""
from .recomputed_resnet import RecomputedResNet
from .recomputed_swin import RecomputedSwinTransformer

__all__ = ['RecomputedResNet', 'RecomputedSwinTransformer']
