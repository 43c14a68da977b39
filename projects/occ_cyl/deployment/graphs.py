"""OccCylindrical's dense parts on plain tensors, for ONNX export.

OccCylindrical runs image encoder -> DepthNet (with the cylindrical
position embedding of the frustum) -> LiDAR point branch -> TPV-Polar-
Fusion (lift-pool into the cylinder, group pooling, dynamic fusion) -> TPV
plane encoder -> head (:meth:`~projects.occ_cyl.OccCylindrical.
extract_feat`). Two parts export as they are:

* :class:`OccCylCameraGraph`: images and camera matrices -> ``V_depth``
  and ``V_context`` (the frustum, its position embedding and BEVDepth's
  camera parameters are computed in the graph);
* :class:`OccCylPlaneGraph`: the three fused TPV planes -> occupancy
  logits and labels (Swin plane encoder, FPN, head).

The part between them runs in PyTorch beside the runtime; docs/export.md
lists why it does not export yet (:data:`MIDDLE_OUTSIDE`).
"""
from typing import Dict, List, Tuple

import torch
from torch import Tensor, nn

from projects.occ_common.deployment.graph_spec import GraphSpec
from projects.occ_common.deployment.image_preprocess import \
    GraphImagePreprocess
from projects.occ_common.deployment.samples import camera_feeds
from projects.occ_common.models.layers import camera_parameter_vector

#: Inputs of :class:`OccCylCameraGraph`.
CAMERA_INPUT_NAMES = ('imgs', 'cam2img', 'lidar2cam', 'img_aug_matrix',
                      'lidar2img')
#: Inputs of :class:`OccCylPlaneGraph`: planes (R, Theta), (Theta, Z),
#: (R, Z).
PLANE_INPUT_NAMES = ('plane_r_theta', 'plane_theta_z', 'plane_r_z')
#: What runs in PyTorch between the two graphs.
MIDDLE_OUTSIDE = (
    'the LiDAR point branch and TPV-Polar-Fusion, in PyTorch between the '
    'camera graph (depth, context) and this one (planes): the cylinder '
    "filter selects points by a boolean mask and the point branch's "
    'empty-cloud branch reads the point count in Python; the lift-pool '
    "voxel list comes from torch.unique and its maximum is index_reduce("
    "'amax'), which the exporter has no form for (as scatter_reduce it "
    "would be ScatterElements(reduction='max'), opset 18); "
    "DynamicFusion2D's shape check reads traced sizes as Python values")


class OccCylCameraGraph(nn.Module):
    """Images -> ``V_depth`` and ``V_context`` of an ``OccCylindrical``.

    Args:
        model (OccCylindrical): In eval mode.
    """

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model
        self.preprocess = GraphImagePreprocess(model.data_preprocessor)

    def forward(self, imgs: Tensor, cam2img: Tensor, lidar2cam: Tensor,
                img_aug_matrix: Tensor,
                lidar2img: Tensor) -> Tuple[Tensor, Tensor]:
        """DepthNet outputs of one sample's views.

        Args:
            imgs (Tensor): The pipeline's images, pixel values 0-255.
                Shape (1, N, 3, H, W).
            cam2img, lidar2cam, img_aug_matrix, lidar2img (Tensor): The
                metainfo matrices. Shape (1, N, 4, 4) each.

        Returns:
            tuple[Tensor, Tensor]: ``depth`` (N, D, h, w) and ``context``
            (N, C, h, w).
        """
        cam_params = None
        if self.model.depth_net.camera_param_dims > 0:
            cam_params = camera_parameter_vector(
                cam2img, lidar2cam, img_aug_matrix).flatten(0, 1)
        out, _ = self.model.lift_images(
            self.preprocess(imgs), lidar2img, cam_params)
        return out['depth'], out['context']


class OccCylPlaneGraph(nn.Module):
    """Fused TPV planes -> finest-scale occupancy of an ``OccCylindrical``.

    Args:
        model (OccCylindrical): In eval mode.
    """

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, plane_r_theta: Tensor, plane_theta_z: Tensor,
                plane_r_z: Tensor) -> Tuple[Tensor, Tensor]:
        """Occupancy logits and labels of the finest scale.

        Args:
            plane_r_theta (Tensor): Shape (1, C, R, Theta).
            plane_theta_z (Tensor): Shape (1, C, Theta, Z).
            plane_r_z (Tensor): Shape (1, C, R, Z).

        Returns:
            tuple[Tensor, Tensor]: ``occ_logits`` (1, K, X, Y, Z) and
            ``occ_labels`` (1, X, Y, Z), int64.
        """
        logits = self.model.decode(
            (plane_r_theta, plane_theta_z, plane_r_z))
        return logits[0], self.model.occ_head.predict(logits)


def fused_planes(model: nn.Module, batch: dict) -> List[Tensor]:
    """The TPV planes PyTorch's forward hands the plane encoder.

    Returns:
        list[Tensor]: The three planes (1, C, H_k, W_k).
    """
    import copy
    seen = []
    hook = model.tpv_encoder.register_forward_hook(
        lambda module, args, result: seen.append(list(args[0])))
    try:
        with torch.no_grad():
            data = model.data_preprocessor(copy.copy(batch), False)
            model.extract_feat(data['inputs'], data['data_samples'])
    finally:
        hook.remove()
    return seen[0]


def occcyl_graph_specs(model: nn.Module) -> List[GraphSpec]:
    """The plane graph (the prediction) and the camera graph.

    Args:
        model (OccCylindrical): In eval mode.

    Returns:
        list[GraphSpec]: Both graphs; all their axes are static.
    """

    def plane_feeds(batch: dict) -> Dict[str, Tensor]:
        return dict(zip(PLANE_INPUT_NAMES, fused_planes(model, batch)))

    def cam_feeds(batch: dict) -> Dict[str, Tensor]:
        feeds = camera_feeds(batch)
        feeds.pop('points')
        return feeds

    return [
        GraphSpec(
            OccCylPlaneGraph(model).eval(), PLANE_INPUT_NAMES,
            ('occ_logits', 'occ_labels'), {}, plane_feeds,
            'the camera graph (<out>.camera.onnx) then ' + MIDDLE_OUTSIDE),
        GraphSpec(
            OccCylCameraGraph(model).eval(),
            CAMERA_INPUT_NAMES, ('depth', 'context'), {},
            cam_feeds, '', part='camera')
    ]
