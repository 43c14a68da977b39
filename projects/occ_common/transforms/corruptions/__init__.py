"""Sensor corruptions of camera + LiDAR samples, applied on the fly.

One registered transform, :class:`OccCorruption`, applies one condition of
:data:`CONDITIONS` at one severity; the conditions live by family in
:mod:`.camera` (with the pixel corruptions of :mod:`.pixels`),
:mod:`.lidar` and :mod:`.cross_sensor`, their scales and sources in
:mod:`.conditions`. :func:`with_corruption` puts the transform into a
config's pipeline.
"""
from .conditions import CONDITIONS, MAX_SEVERITY, Condition
from .occ_corruption import OccCorruption
from .pipeline import with_corruption
from .seeding import corruption_rng

__all__ = [
    'CONDITIONS', 'MAX_SEVERITY', 'Condition', 'OccCorruption',
    'corruption_rng', 'with_corruption'
]
