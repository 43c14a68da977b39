"""Models shared by the occupancy plugins: the base detector, losses,
layers, the sparse backend and checked pretrained-weight loading."""
from . import detectors, layers, losses, pretrained, sparse

__all__ = ['detectors', 'layers', 'losses', 'pretrained', 'sparse']
