"""SDG-KL's prediction path on plain tensors, for ONNX export.

At inference SDG-KL (and the camera rows of Table 3) run images ->
DepthNet -> SDG view transform guided by the key-frame LiDAR points ->
``camera_bev_conv`` -> BEV encoder -> channel-to-height head
(:meth:`~projects.sdg_occ.SDGOcc.extract_feat`); the SPVCNN branch and the
fusion are training-only. :class:`SDGCameraGraph` calls the model's own
tensor-level core of that path (:meth:`~projects.sdg_occ.SDGOcc.camera_bev`
and :meth:`~projects.sdg_occ.SDGOcc.decode`), so that the whole path is
one graph whose inputs are the images, the camera matrices the model
reads from the metainfo and the LiDAR points (any number of them).
Nothing of the sample it is traced with stays in the graph: every inverse
is computed in it, the depth map is a min-scatter, the virtual points are
all pooled with weight 0 where invalid, the LSS indices are recomputed.
That is the GPU code path of :mod:`projects.occ_common.utils.device_path`,
which the export takes (:func:`~projects.occ_common.deployment.
export_graph`).
"""
from typing import Optional, Tuple

from torch import Tensor, nn

from projects.occ_common.deployment.image_preprocess import \
    GraphImagePreprocess
from projects.occ_common.models.layers.camera_geometry import \
    camera_parameter_vector

#: Graph input names, in the order of :meth:`SDGCameraGraph.forward`.
INPUT_NAMES = ('imgs', 'points', 'cam2img', 'lidar2cam', 'img_aug_matrix',
               'lidar2img')
#: Graph output names; ``camera_bev`` only ``with_bev``.
OUTPUT_NAMES = ('occ_logits', 'occ_labels', 'camera_bev')


class SDGCameraGraph(nn.Module):
    """The camera BEV -> occupancy path of an ``SDGOcc`` on tensors.

    Only single-frame models whose inference needs no LiDAR encoder:
    ``variant='kl'`` (SDG-KL's student) and ``'camera'``. SDG-Fusion's
    dense part is :class:`~.fusion_graph.SDGFusionDenseGraph`.

    Args:
        model (SDGOcc): The detector, in eval mode.
        time_dim (int, optional): Column of the points' time lag (the
            metainfo ``points_time_dim``): only rows with lag 0 (the key
            frame) guide the view transform. None: every row does.
            Defaults to None.
        with_bev (bool): Also output the camera BEV F_bev^C, to compare
            a runtime with PyTorch before the head. Defaults to False.
    """

    #: The ``SDGOcc.variant`` values this graph is for.
    VARIANTS = ('kl', 'camera')

    def __init__(self, model: nn.Module,
                 time_dim: Optional[int] = None,
                 with_bev: bool = False) -> None:
        super().__init__()
        name = type(self).__name__
        variant = getattr(model, 'variant', None)
        if variant not in self.VARIANTS:
            raise ValueError(
                f'{name} exports SDGOcc of variant {self.VARIANTS}, got '
                f'{variant!r} (SDG-Fusion: SDGFusionDenseGraph; SDG-KL and '
                'the camera rows: SDGCameraGraph)')
        if getattr(model, 'num_frames', 1) != 1:
            raise ValueError(
                f'{name}: num_frames={model.num_frames} models '
                'fuse the previous frames\' cached BEVs, which a single '
                'graph does not hold; export a single-frame config')
        self.model = model
        self.preprocess = GraphImagePreprocess(model.data_preprocessor)
        self.time_dim = time_dim
        self.with_bev = bool(with_bev)

    def camera_bev(self, imgs: Tensor, points: Tensor, cam2img: Tensor,
                   lidar2cam: Tensor, img_aug_matrix: Tensor,
                   lidar2img: Tensor) -> Tensor:
        """F_bev^C, the camera BEV after ``camera_bev_conv``.

        Args: as :meth:`forward`.

        Returns:
            Tensor: Shape (1, C, Y, X).
        """
        cam_params = None
        if getattr(self.model.depth_net, 'camera_param_dims', 0) > 0:
            cam_params = camera_parameter_vector(
                cam2img, lidar2cam, img_aug_matrix).flatten(0, 1)
        return self.model.camera_bev(self.preprocess(imgs), lidar2img,
                                     cam_params, [points],
                                     [self.time_dim])[1]['bev']

    def forward(self, imgs: Tensor, points: Tensor, cam2img: Tensor,
                lidar2cam: Tensor, img_aug_matrix: Tensor,
                lidar2img: Tensor) -> Tuple[Tensor, ...]:
        """Occupancy of one sample.

        Args:
            imgs (Tensor): The pipeline's images, pixel values 0-255 in its
                channel order (the graph normalises and pads them as the
                model's data preprocessor does). Shape (1, N, 3, H, W).
            points (Tensor): LiDAR points in the working frame, (x, y, z,
                ...), the time lag in column ``time_dim``.
                Shape (P, C).
            cam2img (Tensor): Intrinsics, padded to 4x4.
                Shape (1, N, 4, 4).
            lidar2cam (Tensor): Extrinsics. Shape (1, N, 4, 4).
            img_aug_matrix (Tensor): Image augmentation. Shape (1, N, 4, 4).
            lidar2img (Tensor): ``img_aug_matrix @ cam2img @ lidar2cam``
                as the metainfo holds it (the model reads it from there;
                a product formed again differs in the last bits, enough
                to move a point across a cell border). Shape (1, N, 4, 4).

        Returns:
            tuple[Tensor, ...]: ``occ_logits`` (1, num_classes, X, Y, Z),
            ``occ_labels`` (1, X, Y, Z) int64 and, ``with_bev``,
            ``camera_bev`` (1, C, Y, X).
        """
        bev = self.camera_bev(imgs, points, cam2img, lidar2cam,
                              img_aug_matrix, lidar2img)
        outputs = self.model.decode(bev)
        return outputs + (bev, ) if self.with_bev else outputs
