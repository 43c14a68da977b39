"""Models shared by the occupancy plugins: the base detector, a backbone,
losses, layers, the sparse backend and checked pretrained-weight loading."""
from . import backbones, detectors, layers, losses, pretrained, sparse

__all__ = [
    'backbones', 'detectors', 'layers', 'losses', 'pretrained', 'sparse'
]
