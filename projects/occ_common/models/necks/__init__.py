"""Image necks shared by the occupancy models."""
from .selective_fpn import SelectiveFPN

__all__ = ['SelectiveFPN']
