"""Models shared by the occupancy plugins: the base detector, losses,
layers and the sparse backend."""
from . import detectors, layers, losses, sparse

__all__ = ['detectors', 'layers', 'losses', 'sparse']
