"""Models shared by the occupancy plugins: losses, layers, sparse backend."""
from . import layers, losses, sparse

__all__ = ['layers', 'losses', 'sparse']
