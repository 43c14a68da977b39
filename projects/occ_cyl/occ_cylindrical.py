"""OccCylindrical: camera + LiDAR occupancy through cylindrical TPV planes.

Implements the full model of OccCylindrical (Ming et al., 2025, Fig. 2).
"""
from typing import Dict, List, Optional, Sequence, Tuple

from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample
from mmdet3d.utils import ConfigType, OptConfigType
from torch import Tensor

from projects.occ_common.geometry.depth import num_depth_bins
from projects.occ_common.models.detectors import BaseOccDetector
from projects.occ_common.models.layers import (POSITION_EMBED_DIMS,
                                               cartesian_to_cylindrical,
                                               create_frustum,
                                               cylindrical_position_embedding,
                                               frustum_to_lidar)
from projects.occ_common.utils.eager_island import eager_island
from .cylindrical import CylinderGrid
from .group_pooling import PLANE_POOL_AXES


def _img_shape(sample: Det3DDataSample) -> Tuple[int, int]:
    """``(H, W)`` of the augmented views before padding."""
    shape = sample.metainfo.get('img_shape')
    if shape is None:
        raise ValueError('OccCylindrical: sample '
                         f'{sample.metainfo.get("sample_idx")} has no '
                         'img_shape')
    # Some loaders store one shape per view; the views share one size.
    if isinstance(shape[0], (tuple, list)):
        shape = shape[0]
    return int(shape[0]), int(shape[1])


@MODELS.register_module()
class OccCylindrical(BaseOccDetector):
    """OccCylindrical (camera + LiDAR 3D semantic occupancy).

    Steps 1-8 of the paper: the image encoder gives ``V`` (1/16 of the
    input); :class:`DepthNet` gives ``V_depth`` and ``V_context`` (eq. 5)
    with the cylindrical position embedding of every bin's 3D point; the
    LiDAR point branch (eqs. 2-4) samples ``V_context``; TPV-Polar-Fusion
    lifts the pseudo points and max-pools both clouds into a cylinder,
    group-pools it into three planes per modality and fuses them (eqs.
    6-13); a shared Swin + FPN encodes the planes (eqs. 14-16) and the head
    classifies the Cartesian voxels of four scales (eq. 17). The loss is
    eq. 19: the multi-scale occupancy loss plus the LiDAR depth loss.

    The detector owns the values its children share and builds them with
    those values: the cylinder (one :class:`CylinderGrid` fitted to
    ``point_cloud_range``, given to the fusion and the head; the plane
    encoder must be able to encode its three planes without padding), the
    depth bins (``depth_bound``: DepthNet's bin count, the position
    embedding's ``4 * D`` channels, the depth loss) and the occupancy task
    (grid, classes and labels, see :class:`BaseOccDetector`). A child
    config that sets one of them differently is refused.

    Camera geometry comes from each sample's ``lidar2img`` (or
    ``img_aug_matrix @ cam2img @ lidar2cam``). The data pipeline folds the
    BEV augmentation into every ``lidar2*`` matrix, so ``bda_matrix`` is
    not applied again here.

    Args:
        img_encoder (dict): :class:`MultiViewImageEncoder` config.
        depth_net (dict): :class:`DepthNet` config; its
            ``position_channels`` defaults to ``4 * D`` (the cylindrical
            position embedding), 0 switches the embedding off (Table V).
        point_branch (dict): :class:`LidarPointBranch` config.
        tpv_fusion (dict): :class:`TPVPolarFusion` config.
        tpv_encoder (dict): :class:`TPVPlaneEncoder` config.
        occ_head (dict): :class:`CylindricalOccHead` config.
        point_cloud_range (Sequence[float]): Occupancy grid range, metres.
        voxel_size (Sequence[float]): Occupancy voxel size, metres.
        num_classes (int): Occupancy classes, empty included.
        cylinder (dict): ``shape`` (cells ``(R, Theta, Z)``) and optionally
            ``radius`` and ``clamp`` of :meth:`CylinderGrid.for_box`.
        depth_bound (Sequence[float]): ``(min, max, step)`` of the depth
            bins in metres.
        loss_depth (dict, optional): Depth loss (``DepthBCELoss``); None
            removes the depth supervision (Table V). Defaults to None.
        **kwargs: ``empty_index``, ``ignore_index``, ``loss_mask_key``,
            ``loss_seg``, ``seg_empty_label``, ``pretrained``,
            ``data_preprocessor`` and ``init_cfg`` of
            :class:`BaseOccDetector`. ``loss_seg`` (not in the paper, whose
            image backbone is ImageNet-pretrained) trains the DepthNet's
            semantic head (``seg_channels``) on the LiDAR's projected
            lidarseg labels, as SDG-OCC does; it needs a train pipeline
            with ``gt_seg_2d``.
    """

    def __init__(self,
                 img_encoder: ConfigType,
                 depth_net: ConfigType,
                 point_branch: ConfigType,
                 tpv_fusion: ConfigType,
                 tpv_encoder: ConfigType,
                 occ_head: ConfigType,
                 point_cloud_range: Sequence[float],
                 voxel_size: Sequence[float],
                 num_classes: int,
                 cylinder: dict,
                 depth_bound: Sequence[float],
                 loss_depth: OptConfigType = None,
                 **kwargs) -> None:
        super().__init__(
            point_cloud_range,
            voxel_size,
            num_classes,
            depth_bound=depth_bound,
            loss_depth=loss_depth,
            **kwargs)
        cylinder = dict(cylinder)
        unknown = set(cylinder) - {'shape', 'radius', 'clamp'}
        if 'shape' not in cylinder or unknown:
            raise ValueError('OccCylindrical: cylinder needs shape and may '
                             f'give radius and clamp, got {cylinder}')
        self.cylinder = CylinderGrid.for_box(self.point_cloud_range,
                                             **cylinder)
        num_bins = num_depth_bins(self.depth_bound)
        self.img_encoder = MODELS.build(img_encoder)
        self.depth_net = self.build_child(
            depth_net,
            depth_bound=self.depth_bound,
            position_channels=POSITION_EMBED_DIMS * num_bins)
        self.point_branch = MODELS.build(point_branch)
        self.tpv_fusion = self.build_child(tpv_fusion, cylinder=self.cylinder)
        self.tpv_encoder = MODELS.build(tpv_encoder)
        self.occ_head = self.build_child(
            occ_head,
            cylinder=self.cylinder,
            point_cloud_range=self.point_cloud_range,
            voxel_size=self.voxel_size,
            **self.head_defaults())
        for child in (self.depth_net, self.loss_depth):
            if child is not None:
                self.check_child(child, depth_bound=self.depth_bound)
        if self.loss_seg is not None and self.depth_net.seg_channels < 1:
            raise ValueError('OccCylindrical: loss_seg needs a DepthNet '
                             'with seg_channels > 0')
        if self.depth_net.num_depth_bins != num_bins:
            raise ValueError(
                f'OccCylindrical: depth_bound {self.depth_bound} gives '
                f'{num_bins} bins but depth_net predicts '
                f'{self.depth_net.num_depth_bins}')
        if self.depth_net.position_channels not in (
                0, POSITION_EMBED_DIMS * num_bins):
            raise ValueError(
                'OccCylindrical: depth_net.position_channels must be 0 (no '
                f'position embedding) or {POSITION_EMBED_DIMS} * {num_bins} '
                f'bins, got {self.depth_net.position_channels}')
        for _, kept in PLANE_POOL_AXES:
            self.tpv_encoder.check_plane_shape(
                [self.cylinder.shape[a - 1] for a in kept],
                '(' + ', '.join('R Theta Z'.split()[a - 1]
                                for a in kept) + ')')
        self.check_child(
            self.occ_head.loss_occ,
            empty_index=self.empty_index,
            ignore_index=self.ignore_index)

    def lift_images(self, imgs: Tensor, lidar2img: Tensor,
                    cam_params: Optional[Tensor]) -> Tuple[dict, Tensor]:
        """Image encoder and DepthNet: every view's depth and context, and
        where the frustum's points lie (steps 1-2).

        Args:
            imgs (Tensor): Normalised images. Shape (B, N, 3, H, W).
            lidar2img (Tensor): Shape (B, N, 4, 4).
            cam_params (Tensor, optional): BEVDepth's camera parameters
                when DepthNet reads them. Shape (B*N, camera_param_dims).

        Returns:
            tuple: DepthNet's outputs (``depth`` Shape (B*N, D, h, w),
            ``context`` Shape (B*N, C, h, w), ...) and the frustum's
            points in the LiDAR frame, Shape (B, N, D, h, w, 3).
        """
        feats = self.img_encoder(imgs)
        frustum = create_frustum(tuple(imgs.shape[-2:]), feats.shape[-2:],
                                 self.depth_bound)
        cam_points = frustum_to_lidar(frustum, lidar2img)
        pos_embed = None
        if self.depth_net.position_channels > 0:
            pos_embed = cylindrical_position_embedding(
                cam_points, self.cylinder.cyl_range)
        return self.depth_net(feats, pos_embed, cam_params), cam_points

    def extract_feat(self, batch_inputs_dict: dict,
                     batch_data_samples: List[Det3DDataSample]) -> dict:
        """Run the network up to the head's logits.

        Args:
            batch_inputs_dict (dict): ``imgs`` Shape (B, N, 3, H, W) and
                ``points`` list of Shape (P_i, C).
            batch_data_samples (list[Det3DDataSample]): Samples with the
                camera metainfo.

        Returns:
            dict: ``logits`` (list per scale, finest first, each
            Shape (B, K, X_l, Y_l, Z_l)), ``depth`` Shape (B*N, D, h, w)
            and, with a semantic head, ``seg_logits`` Shape
            (B*N, seg_channels, h, w).
        """
        imgs = batch_inputs_dict.get('imgs')
        points = batch_inputs_dict.get('points')
        if imgs is None or points is None:
            raise ValueError('OccCylindrical needs inputs "imgs" and '
                             f'"points", got {sorted(batch_inputs_dict)}')
        if len(batch_data_samples) != imgs.shape[0]:
            raise ValueError(f'OccCylindrical: {imgs.shape[0]} image sets '
                             f'for {len(batch_data_samples)} data samples')
        batch_size, num_cams = imgs.shape[:2]
        input_shape = tuple(imgs.shape[-2:])
        lidar2img = self.lidar2img(batch_data_samples, imgs.device)
        if lidar2img.shape[1] != num_cams:
            raise ValueError(f'OccCylindrical: {num_cams} images but '
                             f'{lidar2img.shape[1]} camera matrices')

        cam_params = None
        if self.depth_net.camera_param_dims > 0:
            cam_params = self.camera_params(batch_data_samples, imgs.device)
        out, cam_points = self.lift_images(imgs, lidar2img, cam_params)
        depth, context = out['depth'], out['context']

        points, lidar_feats = self.lidar_features(
            points, context.unflatten(0, (batch_size, num_cams)), lidar2img,
            input_shape, [_img_shape(s) for s in batch_data_samples])
        planes = self.tpv_fusion(depth, context, cam_points, lidar_feats,
                                 [p[:, :3] for p in points])
        result = dict(logits=self.decode(planes), depth=depth)
        if 'seg_logits' in out:
            result['seg_logits'] = out['seg_logits']
        return result

    def decode(self, planes: Sequence[Tensor]) -> List[Tensor]:
        """TPV plane encoder and head: the fused planes' occupancy logits
        per scale (steps 5-6), on tensors (shared with the ONNX plane
        graph).

        Args:
            planes (Sequence[Tensor]): The fused TPV planes (R, Theta),
                (Theta, Z), (R, Z), each Shape (B, C, H_k, W_k).

        Returns:
            list[Tensor]: Logits per scale, finest first, each
            Shape (B, K, X_l, Y_l, Z_l).
        """
        return self.occ_head(self.tpv_encoder(planes))

    @eager_island
    def lidar_features(self, points: List[Tensor], context: Tensor,
                       lidar2img: Tensor, input_shape: Tuple[int, int],
                       img_shapes: List[Tuple[int, int]]
                       ) -> Tuple[List[Tensor], List[Tensor]]:
        """The points that reach a voxel and their features (eqs. 2-4).

        Points outside the cylinder could not reach any voxel (with a
        clamping cylinder, only non-finite points are dropped). How many
        remain, and which cameras see which, the data decides: under
        ``torch.compile`` this step is an eager island (one graph break),
        its outputs' point counts dynamic, so that no point count
        recompiles the graphs around it.

        Args:
            points (list[Tensor]): Per sample. Shape (P_i, C).
            context (Tensor): ``V_context``. Shape (B, N, C_ctx, h, w).
            lidar2img (Tensor): Shape (B, N, 4, 4).
            input_shape (tuple[int, int]): Padded network input.
            img_shapes (list[tuple[int, int]]): Per sample, the augmented
                image before padding.

        Returns:
            tuple[list[Tensor], list[Tensor]]: The kept points, each
            Shape (P'_i, C), and the point branch's features, each
            Shape (P'_i, C_point).
        """
        points = [
            p[self.cylinder.voxel_coords(cartesian_to_cylindrical(p[:, :3]))
              [1]] for p in points
        ]
        return points, self.point_branch(points, context, lidar2img,
                                         input_shape, img_shapes)

    def loss(self, batch_inputs_dict: dict,
             batch_data_samples: List[Det3DDataSample]) -> Dict[str, Tensor]:
        """Eq. 19: multi-scale occupancy loss plus the depth loss (and
        ``loss_seg`` where configured).

        Args:
            batch_inputs_dict (dict): See :meth:`extract_feat`.
            batch_data_samples (list[Det3DDataSample]): With ``gt_occ``
                Shape (X, Y, Z) and, for the depth and semantic losses,
                ``gt_depth`` Shape (N, H, W) (and ``gt_seg_2d``).

        Returns:
            dict[str, Tensor]: Loss terms.
        """
        out = self.extract_feat(batch_inputs_dict, batch_data_samples)
        device = out['depth'].device
        losses = self.occ_head.loss(
            out['logits'], self.occupancy_targets(batch_data_samples, device))
        if self.loss_depth is not None or self.loss_seg is not None:
            imgs = batch_inputs_dict['imgs']
            gt_depth = self.gt_depth(batch_data_samples, device,
                                     imgs.shape[-2:])
            losses.update(self.depth_losses(out['depth'], gt_depth))
            losses.update(
                self.seg_losses(out, batch_data_samples, gt_depth,
                                imgs.shape[-1] // out['depth'].shape[-1]))
        return losses

    def predict(self, batch_inputs_dict: dict,
                batch_data_samples: List[Det3DDataSample]
                ) -> List[Det3DDataSample]:
        """Predict the finest-scale occupancy.

        Args:
            batch_inputs_dict (dict): See :meth:`extract_feat`.
            batch_data_samples (list[Det3DDataSample]): Input samples.

        Returns:
            list[Det3DDataSample]: The input samples with ``pred_occ``
            Shape (X, Y, Z) int64 (their ``gt_occ`` and ``mask_camera``, if
            any, stay in place for the metric).
        """
        out = self.extract_feat(batch_inputs_dict, batch_data_samples)
        return self.add_pred_occ(batch_data_samples,
                                 self.occ_head.predict(out['logits']))

    def _forward(self, batch_inputs_dict: dict,
                 batch_data_samples: List[Det3DDataSample]) -> List[Tensor]:
        """Raw logits per scale, finest first (``mode='tensor'``)."""
        return self.extract_feat(batch_inputs_dict,
                                 batch_data_samples)['logits']
