"""OccCylindrical: multi-modal occupancy through cylindrical TPV planes.

The model of OccCylindrical (Ming et al., 2025).

Importing this package registers ``MultiViewImageEncoder``,
``LidarPointBranch``, ``SpatialGroupPooling``, ``DynamicFusion2D``,
``TPVPolarFusion``, ``TPVPlaneEncoder``, ``CylindricalOccHead`` and
``OccCylindrical`` in mmdet3d's ``MODELS`` registry (``DepthNet`` comes from
``projects.occ_common``).
"""
from .cylindrical import CylinderGrid
from .cylindrical_occ_head import CylindricalOccHead
from .dynamic_fusion import DynamicFusion2D
from .group_pooling import SpatialGroupPooling
from .image_branch import MultiViewImageEncoder
from .lift_pool import (LiftMaxPoolFunction, lift_max_pool,
                        naive_lift_max_pool, voxel_max_pool)
from .occ_cylindrical import OccCylindrical
from .point_branch import LidarPointBranch, sample_image_features
from .tpv_encoder import TPVPlaneEncoder
from .tpv_polar_fusion import TPVPolarFusion

__all__ = [
    'CylinderGrid', 'CylindricalOccHead', 'DynamicFusion2D',
    'LidarPointBranch', 'LiftMaxPoolFunction', 'MultiViewImageEncoder',
    'OccCylindrical', 'SpatialGroupPooling', 'TPVPlaneEncoder',
    'TPVPolarFusion', 'lift_max_pool', 'naive_lift_max_pool',
    'sample_image_features', 'voxel_max_pool'
]
