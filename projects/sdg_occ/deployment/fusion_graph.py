"""SDG-Fusion's dense part on plain tensors, for ONNX export.

SDG-Fusion fuses the camera BEV (queries) with the SPVCNN LiDAR BEV
(keys, values) by neighbourhood attention, then decodes the fused BEV
(:meth:`~projects.sdg_occ.SDGOcc.fuse`). The SPVCNN encoder's sparse
convolutions (a voxel count read on the host, hash maps, ``searchsorted``)
have no ONNX form that runtimes execute well, so, as the peers run sparse
convolutions in their own engine, it stays outside the graph:
:class:`SDGFusionDenseGraph` takes its BEV as an input
(``model.lidar_encoder([points])['bev']``, computed by PyTorch or spconv
beside the runtime) and holds everything else: the camera branch of
:class:`~.camera_graph.SDGCameraGraph`, the fusion, the BEV encoder and
the head.
"""
from typing import Tuple

from torch import Tensor

from .camera_graph import INPUT_NAMES as CAMERA_INPUT_NAMES
from .camera_graph import SDGCameraGraph

#: Graph input names, in the order of :meth:`SDGFusionDenseGraph.forward`.
INPUT_NAMES = CAMERA_INPUT_NAMES + ('lidar_bev', )


class SDGFusionDenseGraph(SDGCameraGraph):
    """SDG-Fusion without its LiDAR encoder, on tensors.

    Args:
        model (SDGOcc): ``variant='fusion'``, single frame, in eval mode.
        time_dim (int, optional): As for :class:`SDGCameraGraph`.
        with_bev (bool): Also output the camera BEV. Defaults to False.
    """

    VARIANTS = ('fusion', )

    def forward(self, imgs: Tensor, points: Tensor, cam2img: Tensor,
                lidar2cam: Tensor, img_aug_matrix: Tensor, lidar2img: Tensor,
                lidar_bev: Tensor) -> Tuple[Tensor, ...]:
        """Occupancy of one sample from its images, points and LiDAR BEV.

        Args:
            imgs, points, cam2img, lidar2cam, img_aug_matrix, lidar2img: As
                for
                :meth:`SDGCameraGraph.forward`; the points guide the view
                transform.
            lidar_bev (Tensor): The LiDAR encoder's BEV of the same points.
                Shape (1, C_lidar, Y, X).

        Returns:
            tuple[Tensor, ...]: As :meth:`SDGCameraGraph.forward`.
        """
        bev = self.camera_bev(imgs, points, cam2img, lidar2cam,
                              img_aug_matrix, lidar2img)
        outputs = self.model.decode(self.model.fusion(bev, lidar_bev))
        return outputs + (bev, ) if self.with_bev else outputs
