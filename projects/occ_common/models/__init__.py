"""Models shared by the occupancy plugins: the base detector, backbones, a
neck, losses, layers, the sparse backend and checked pretrained-weight
loading."""
from . import backbones, detectors, layers, losses, necks, pretrained, sparse

__all__ = [
    'backbones', 'detectors', 'layers', 'losses', 'necks', 'pretrained',
    'sparse'
]
