"""Base of the occupancy detectors (the models themselves live in their
projects: ``projects.occ_cyl``, ``projects.sdg_occ``)."""
from .base_occ_detector import BaseOccDetector

__all__ = ['BaseOccDetector']
