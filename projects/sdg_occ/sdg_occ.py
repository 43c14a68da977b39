"""SDG-OCC detector: SDG-Fusion, SDG-KL and the camera-only rows.

Implements the full model of SDG-OCC (Duan et al., CVPR 2025, Fig. 3):
image backbone and FPN, the multi-task DepthNet (context, depth, 2D
semantics), the SDG view transformation into a camera BEV, an SPVCNN LiDAR
BEV, neighbourhood-attention fusion, the BEV encoder and the
channel-to-height occupancy head.

The variant is what the configured sub-modules make of it
(:attr:`SDGOcc.variant`), not a separate switch:

* a ``lidar_encoder`` and a ``fusion`` without ``loss_distill``:
  SDG-Fusion (Fig. 5a): the camera BEV is the source
  (queries) of the fusion and the LiDAR BEV the cross feature (keys,
  values), Sec. 3.5; the fused BEV goes to the head, in training and
  inference.
* with a ``loss_distill`` too: SDG-KL (Fig. 5b): in training a
  LiDAR-dominant fusion (LiDAR queries, camera keys and values) is a
  teacher and FOAD distils it into the camera BEV; at inference the LiDAR
  encoder and the fusion are skipped and the camera BEV goes to the head.
  ``kl_losses`` says what else trains: ``'paper'`` is Sec. 3.5 as written,
  "the sum of distillation and classification loss", one occupancy loss
  on the fused BEV through the one BEV encoder and head that the camera
  BEV then uses at inference; ``'three_loss'`` (the constructor's default,
  for configs written before) adds the student's own occupancy loss and
  supervises the teacher separately, with the student's decoder or
  (``separate_teacher_head``) its own training-only copies.
* neither: the camera rows (the Baseline and "+SDG" rows of Table 3): no
  LiDAR encoder, no fusion; the camera BEV goes to the head. With the plain LSS
  lift this is the FlashOcc-like baseline, which needs no LiDAR points at
  all; with the SDG lift the points still guide the view transform.

The camera BEV is one step, :meth:`SDGOcc.extract_camera_bev`, whose
per-frame core (:meth:`SDGOcc.camera_bev`) and decoder
(:meth:`SDGOcc.decode`) take plain tensors, so that the ONNX graphs
(:mod:`.deployment`) call the model's own inference instead of restating
it. The view
transform pools the lifted features, then a learned 3x3 conv-BN
(``camera_bev_conv``) gives the BEV that the fusion, the head and FOAD see.
With ``num_frames`` T > 1 (the T-frame input of Sec. 3.1) that step also
warps the previous frames' camera BEVs into the current frame and reduces
the T of them to one (:mod:`.temporal_fusion`); everything after it is
unchanged, so SDG-KL distils into the temporally fused camera BEV.
"""
from typing import Dict, List, Optional, Sequence, Tuple

import torch
from mmdet3d.registry import MODELS
from torch import Tensor, nn

from projects.occ_common.models.detectors import BaseOccDetector
from projects.occ_common.models.sparse.point_seg_head import \
    gather_point_labels
from .temporal_fusion import (FrameBEVCache, TemporalBEVFusion, frame_points,
                              frame_samples)

_VARIANTS = ('camera', 'fusion', 'kl')
#: SDGOcc's ``kl_losses``: what trains SDG-KL besides FOAD.
KL_LOSSES = ('paper', 'three_loss')


def configured_variant(lidar_encoder: Optional[dict], fusion: Optional[dict],
                       loss_distill: Optional[dict]) -> str:
    """The variant the configured sub-modules make.

    Args:
        lidar_encoder, fusion, loss_distill (dict, optional): The
            detector's arguments of those names.

    Returns:
        str: ``'camera'`` without a fusion, ``'kl'`` with a distillation
        loss, else ``'fusion'``.

    Raises:
        ValueError: For a combination that is none of them (a LiDAR
            encoder without a fusion or the other way round, or a
            distillation loss without both).
    """
    if not (lidar_encoder or fusion):
        if loss_distill:
            raise ValueError('SDGOcc: loss_distill (SDG-KL) needs a '
                             'lidar_encoder and a fusion (its teacher)')
        return 'camera'
    if not (lidar_encoder and fusion):
        raise ValueError('SDGOcc: a LiDAR branch needs both a lidar_encoder '
                         'and a fusion; set both, or both to None for the '
                         'camera rows')
    return 'kl' if loss_distill else 'fusion'


@MODELS.register_module()
class SDGOcc(BaseOccDetector):
    """SDG-OCC multi-modal occupancy network.

    The detector owns the values its children share and builds them with
    those values (see :class:`BaseOccDetector`): the occupancy grid
    (``point_cloud_range`` and the ``(Y, X)`` BEV of ``voxel_size`` for the
    view transform and the LiDAR encoder, the ``Z`` height cells, classes
    and labels for the head) and the depth bins (``depth_bound`` for the
    DepthNet, the view transform and the depth loss). A child config that
    sets one of them differently is refused.

    Args:
        img_backbone (dict): Image backbone (e.g. ``mmdet.ResNet``).
        img_neck (dict): Image neck to stride ``downsample``
            (``SelectiveFPN``); its first output is used, so a neck should
            build no other (DDP refuses parameters without gradient).
        depth_net (dict): ``DepthNet``; ``seg_channels > 0`` for the SDG
            lift.
        view_transform (dict): ``SDGViewTransform``.
        bev_encoder (dict): ``SDGBEVEncoder``.
        occ_head (dict): ``ChannelToHeightHead``.
        point_cloud_range (Sequence[float]): Occupancy grid range, metres.
        voxel_size (Sequence[float]): Occupancy voxel size, metres; one BEV
            cell per voxel column.
        num_classes (int): Occupancy classes, empty included.
        depth_bound (Sequence[float]): ``(min, max, step)`` of the depth
            bins, metres.
        variant (str, optional): Configs written before the variant was
            read off the sub-modules name it (``'camera'``, ``'fusion'``
            or ``'kl'``); it must then agree with them
            (:func:`configured_variant`). Defaults to None.
        lidar_encoder (dict, optional): ``SPVCNNEncoder``, its BEV on the
            camera BEV grid; with ``fusion``, SDG-Fusion or (with
            ``loss_distill``) SDG-KL. Defaults to None.
        fusion (dict, optional): ``NeighborhoodFusion``. The detector
            gives it its widths: for SDG-Fusion the camera BEV is the
            source and the LiDAR BEV the cross feature, for SDG-KL's
            teacher the other way round, and the output has the camera
            BEV's width. Defaults to None.
        loss_distill (dict, optional): ``FOADDistillLoss``: makes the model
            SDG-KL. Defaults to None.
        point_seg_head (dict, optional): ``PointSegHead`` on the LiDAR
            encoder's point features, trained with the lidarseg labels
            (``loss_point_seg``), as the authors' release trains its SPVCNN
            (not in the paper); needs a ``lidar_encoder`` and the points'
            labels. Defaults to None.
        loss_depth (dict, optional): ``DepthBCELoss``. Defaults to None.
        loss_seg (dict, optional): 2D semantic loss on (N, C) logits, e.g.
            ``mmdet.CrossEntropyLoss`` with ``ignore_index=255``.
            Defaults to None.
        kl_losses (str): ``'kl'`` only: which losses train SDG-KL.
            ``'paper'``: one occupancy (classification) loss, on the
            teacher's fused BEV decoded by the model's one BEV encoder and
            head, plus FOAD (eq. 8), as Sec. 3.5 writes ("trained with the
            sum of distillation and classification loss") and the authors'
            release trains (one head, its loss on the fused path); the
            camera BEV meets that head at inference. ``'three_loss'``:
            the student's own occupancy loss, the teacher's (times
            ``teacher_loss_weight``, with ``separate_teacher_head``) and
            FOAD. Defaults to 'three_loss', the form of configs written
            before 2026-11-28; the SDG-KL configs set 'paper'.
        teacher_loss_weight (float): Factor of the teacher's occupancy
            losses in ``'kl'`` training with ``kl_losses='three_loss'``.
            Defaults to 1.0.
        separate_teacher_head (bool): ``kl_losses='three_loss'`` only.
            False (the default) decodes the teacher's fused BEV with the
            student's BEV encoder and head, one set of weights fitting
            both; True gives the teacher its own BEV encoder and head
            (``teacher_bev_encoder``, ``teacher_occ_head``, training
            only), so the inference head fits the camera BEV alone and
            FOAD is the only link between the two.
        detach_teacher_camera (bool): ``'kl'`` only. False (the default)
            lets the fused BEV's occupancy loss reach the camera branch
            through the camera keys and values of the fusion; True feeds
            the fusion a detached camera BEV, so that the camera branch
            learns from FOAD (and, with ``'three_loss'``, its own
            occupancy loss) alone (the paper does not say which).
        seg_empty_label (int, optional): 2D semantic target of feature
            cells that no labelled LiDAR return hits. None (the default)
            ignores them: nothing says what such a cell shows, and a label
            of 0 there would teach the head to predict "no class" exactly
            where LiDAR depth is missing, which is where eq. 2 of the
            semantic diffusion then refuses to fill a depth (on the tiny
            synthetic world's two key frames it filled 5 and 11 of 1,056
            cells instead of 292 and 271).
        downsample (int): Image-to-feature stride. Defaults to 16.
        num_frames (int): T, frames of camera input (the current one and
            T - 1 previous key frames, see :mod:`.temporal_fusion`). 1 (the
            default) is the single-frame model, unchanged.
        test_cache (bool): With T > 1, reuse at test time each frame's
            camera BEV for the next frame (a sequential loader then runs
            about one frame's image backbone per sample). Defaults to True.
        predict_branch (str): ``'kl'`` only. ``'student'`` (the default)
            predicts from the camera BEV, the paper's inference; ``'teacher'``
            from the fused BEV through the teacher's BEV encoder and head
            (LiDAR needed), to score the teacher with ``tools/test.py``.
        **kwargs: ``empty_index``, ``ignore_index``, ``loss_mask_key``,
            ``data_preprocessor`` and ``init_cfg`` of
            :class:`BaseOccDetector`.
    """

    def __init__(self,
                 img_backbone: dict,
                 img_neck: dict,
                 depth_net: dict,
                 view_transform: dict,
                 bev_encoder: dict,
                 occ_head: dict,
                 point_cloud_range: Sequence[float],
                 voxel_size: Sequence[float],
                 num_classes: int,
                 depth_bound: Sequence[float],
                 variant: Optional[str] = None,
                 lidar_encoder: Optional[dict] = None,
                 fusion: Optional[dict] = None,
                 loss_distill: Optional[dict] = None,
                 point_seg_head: Optional[dict] = None,
                 loss_depth: Optional[dict] = None,
                 loss_seg: Optional[dict] = None,
                 kl_losses: str = 'three_loss',
                 teacher_loss_weight: float = 1.0,
                 separate_teacher_head: bool = False,
                 detach_teacher_camera: bool = False,
                 seg_empty_label: Optional[int] = None,
                 downsample: int = 16,
                 num_frames: int = 1,
                 test_cache: bool = True,
                 predict_branch: str = 'student',
                 **kwargs):
        super().__init__(
            point_cloud_range,
            voxel_size,
            num_classes,
            depth_bound=depth_bound,
            loss_depth=loss_depth,
            loss_seg=loss_seg,
            seg_empty_label=seg_empty_label,
            **kwargs)
        self._variant = self._check_variant(variant, lidar_encoder, fusion,
                                            loss_distill)
        variant = self._variant
        self.downsample = int(downsample)
        self.teacher_loss_weight = float(teacher_loss_weight)
        bev_shape = (self.occ_shape[1], self.occ_shape[0])  # (Y, X)
        grid = dict(
            point_cloud_range=self.point_cloud_range, bev_shape=bev_shape)
        self.img_backbone = MODELS.build(img_backbone)
        self.img_neck = MODELS.build(img_neck)
        self.depth_net = self.build_child(
            depth_net, depth_bound=self.depth_bound)
        self.view_transform = self.build_child(
            view_transform, depth_bound=self.depth_bound, **grid)
        cam_channels = self.depth_net.context_channels
        # FOAD's student must be a feature the camera branch can change on
        # the inactive region IR (LiDAR occupied, camera BEV empty). The
        # pooled BEV is exactly 0 there whatever the weights, so (T - S)^2
        # on IR would be a constant: eq. 8 distils at F_bev^C "through BEV
        # pooling", here at one learned layer after it. A 3x3 conv reaches
        # the IR cells next to camera-covered ones (LSS leaves gaps between
        # its rays, Fig. 2) and BN's shift reaches every cell; no ReLU, so
        # no cell's gradient is cut. The fusion, the head and FOAD all see
        # this BEV, in every variant, so Table 3's rows differ only in what
        # they ablate.
        self.camera_bev_conv = nn.Sequential(
            nn.Conv2d(cam_channels, cam_channels, 3, padding=1, bias=False),
            nn.BatchNorm2d(cam_channels))
        if int(num_frames) < 1:
            raise ValueError(f'SDGOcc num_frames must be >= 1, got '
                             f'{num_frames}')
        self.num_frames = int(num_frames)
        self.test_cache = bool(test_cache)
        # T = 1 adds no module, so its state dict is today's.
        self.temporal_fusion = None
        if self.num_frames > 1:
            self.temporal_fusion = TemporalBEVFusion(cam_channels,
                                                     self.num_frames)
        self.bev_cache = FrameBEVCache(capacity=4 * self.num_frames)
        self.bev_encoder = MODELS.build(bev_encoder)
        self.occ_head = self.build_child(
            occ_head, dz=self.occ_shape[2], **self.head_defaults())
        for name, value in (('separate_teacher_head', separate_teacher_head),
                            ('detach_teacher_camera', detach_teacher_camera)):
            if value and variant != 'kl':
                raise ValueError(f'SDGOcc: {name} is for '
                                 f"variant='kl' only, got {variant!r}")
        self.detach_teacher_camera = bool(detach_teacher_camera)
        self.kl_losses = self._check_kl_losses(
            kl_losses, variant, separate_teacher_head, teacher_loss_weight)
        if predict_branch not in ('student', 'teacher'):
            raise ValueError("SDGOcc predict_branch must be 'student' or "
                             f"'teacher', got {predict_branch!r}")
        if predict_branch == 'teacher' and variant != 'kl':
            raise ValueError("SDGOcc: predict_branch='teacher' is for "
                             f"variant='kl' only, got {variant!r}")
        self.predict_branch = predict_branch
        self.teacher_bev_encoder = self.teacher_occ_head = None
        if separate_teacher_head:
            self.teacher_bev_encoder = MODELS.build(bev_encoder)
            self.teacher_occ_head = self.build_child(
                occ_head, dz=self.occ_shape[2], **self.head_defaults())
        self.lidar_encoder = self.build_child(lidar_encoder, **grid)
        self.point_seg_head = None
        if point_seg_head:
            if self.lidar_encoder is None:
                raise ValueError('SDGOcc: point_seg_head reads the LiDAR '
                                 "encoder's point features; set a "
                                 'lidar_encoder or point_seg_head=None')
            self.point_seg_head = MODELS.build(
                point_seg_head,
                default_args=dict(
                    in_channels=self.lidar_encoder.point_channels))
        self.fusion = None
        if fusion:
            self.fusion = self.build_child(
                fusion, **self._fusion_channels(cam_channels))
            self.check_child(self.fusion,
                             **self._fusion_channels(cam_channels))
        self.loss_distill = self.build_child(loss_distill)
        for child in (self.depth_net, self.view_transform, self.loss_depth):
            if child is not None:
                self.check_child(child, depth_bound=self.depth_bound)
        for child in (self.view_transform, self.lidar_encoder):
            if child is not None:
                self.check_child(child, **grid)
        self.check_child(
            self.occ_head, dz=self.occ_shape[2], num_classes=num_classes)
        self.check_child(
            self.occ_head.loss_occ,
            empty_index=self.empty_index,
            ignore_index=self.ignore_index)

    @staticmethod
    def _check_variant(variant: Optional[str], lidar_encoder, fusion,
                       loss_distill) -> str:
        """The configured variant; a named one must agree with it."""
        found = configured_variant(lidar_encoder, fusion, loss_distill)
        if variant is not None and variant not in _VARIANTS:
            raise ValueError(f'SDGOcc variant must be one of {_VARIANTS}, '
                             f'got {variant!r}')
        if variant not in (None, found):
            raise ValueError(
                f'SDGOcc(variant={variant!r}) contradicts its sub-modules, '
                f'which make {found!r} (lidar_encoder and fusion: a LiDAR '
                'branch; loss_distill: SDG-KL). Drop variant; the '
                'sub-modules say it.')
        return found

    @staticmethod
    def _check_kl_losses(kl_losses: str, variant: str,
                         separate_teacher_head: bool,
                         teacher_loss_weight: float) -> str:
        """The checked ``kl_losses``; the teacher-head options belong to
        the three-loss form."""
        if kl_losses not in KL_LOSSES:
            raise ValueError(f'SDGOcc kl_losses must be one of {KL_LOSSES},'
                             f' got {kl_losses!r}')
        if variant == 'kl' and kl_losses == 'paper' and (
                separate_teacher_head or teacher_loss_weight != 1.0):
            raise ValueError(
                "SDGOcc(kl_losses='paper') trains one head with one "
                'occupancy loss (on the fused BEV); separate_teacher_head '
                "and teacher_loss_weight belong to kl_losses='three_loss'")
        return kl_losses

    @property
    def variant(self) -> str:
        """``'camera'``, ``'fusion'`` or ``'kl'``, read off the
        sub-modules (:func:`configured_variant`)."""
        return self._variant

    def _fusion_channels(self, cam_channels: int) -> Dict[str, int]:
        """Widths of the fusion: its source (query) is the camera BEV for
        SDG-Fusion and the LiDAR BEV for SDG-KL's teacher; its output has
        the camera BEV's width (the student's, for FOAD)."""
        lidar_channels = self.lidar_encoder.out_channels
        source, cross = ((cam_channels, lidar_channels)
                         if self.variant == 'fusion' else
                         (lidar_channels, cam_channels))
        return dict(
            source_channels=source,
            cross_channels=cross,
            out_channels=cam_channels)

    # ------------------------------------------------------------------
    # Features
    # ------------------------------------------------------------------
    def extract_img_feat(self, imgs: Tensor) -> Tensor:
        """Image features at stride ``downsample``.

        Args:
            imgs (Tensor): Shape (B, N, 3, H, W).

        Returns:
            Tensor: Shape (B * N, C, H / downsample, W / downsample).
        """
        if imgs.dim() != 5:
            raise ValueError('SDGOcc expects inputs["imgs"] of shape (B, N, '
                             f'3, H, W), got {tuple(imgs.shape)}')
        feats = self.img_neck(self.img_backbone(imgs.flatten(0, 1)))
        if isinstance(feats, (list, tuple)):
            feats = feats[0]
        expected = (imgs.shape[-2] // self.downsample,
                    imgs.shape[-1] // self.downsample)
        if tuple(feats.shape[-2:]) != expected:
            raise ValueError(f'SDGOcc: image features {tuple(feats.shape)} '
                             f'are not at stride {self.downsample} of the '
                             f'images {tuple(imgs.shape)}')
        return feats

    def camera_bev(self, imgs: Tensor, lidar2img: Tensor,
                   cam_params: Optional[Tensor],
                   points: Optional[List[Tensor]],
                   time_dims: Optional[List[Optional[int]]] = None
                   ) -> Tuple[Dict[str, Tensor], Dict[str, Tensor]]:
        """DepthNet outputs and the camera BEV F_bev^C of one frame, on
        tensors: the core that :meth:`frame_camera_bev` and the ONNX graphs
        share.

        Args:
            imgs (Tensor): Normalised images. Shape (B, N, 3, H, W).
            lidar2img (Tensor): Shape (B, N, 4, 4).
            cam_params (Tensor, optional): BEVDepth's camera parameters,
                when the DepthNet reads them. Shape (B * N, P).
            points (list[Tensor], optional): Per sample (P_b, C), for the
                SDG lift (ignored by the plain LSS lift).
            time_dims (list, optional): Per sample, the points' time-lag
                column (None: every row is the key frame).

        Returns:
            tuple[dict, dict]: The DepthNet outputs and the view-transform
            outputs with ``bev`` (B, C, Y, X) after ``camera_bev_conv`` and
            ``bev_pooled``, the view transform's own; ``bev_mask`` (B, 1,
            Y, X) stays the pooled coverage (FOAD's M_img).
        """
        feats = self.extract_img_feat(imgs)
        depth_out = self.depth_net(feats, cam_params=cam_params)
        use_sdg = self.view_transform.use_sdg
        cam = self.view_transform(depth_out['context'], depth_out['depth'],
                                  depth_out.get('seg_logits'),
                                  points if use_sdg else None, lidar2img,
                                  imgs.shape[-2:],
                                  time_dims if use_sdg else None)
        cam['bev_pooled'] = cam['bev']
        cam['bev'] = self.camera_bev_conv(cam['bev'])
        return depth_out, cam

    def frame_camera_bev(self, inputs: dict, data_samples: Sequence
                         ) -> Tuple[Dict[str, Tensor], Dict[str, Tensor]]:
        """DepthNet outputs and the camera BEV F_bev^C of one frame.

        Args:
            inputs (dict): ``imgs`` (B, N, 3, H, W) and, when the SDG lift
                is on, ``points`` (list of (P_b, C) tensors).
            data_samples (Sequence[Det3DDataSample]): Carry ``lidar2img``
                (N, 4, 4) in their metainfo (and ``points_time_dim`` when
                sweeps were merged).

        Returns:
            tuple[dict, dict]: As :meth:`camera_bev`.
        """
        imgs = inputs['imgs']
        if imgs.dim() != 5:
            raise ValueError('SDGOcc expects inputs["imgs"] of shape (B, N, '
                             f'3, H, W), got {tuple(imgs.shape)}')
        device = imgs.device
        cam_params = None
        if getattr(self.depth_net, 'camera_param_dims', 0) > 0:
            cam_params = self.camera_params(data_samples, device)
        lidar2img = self.lidar2img(data_samples, device)
        if lidar2img.shape[:2] != imgs.shape[:2]:
            raise ValueError(f'SDGOcc: lidar2img {tuple(lidar2img.shape)} '
                             f'does not match the images '
                             f'{tuple(imgs.shape[:2])} (B, N)')
        points, time_dims = None, None
        if self.view_transform.use_sdg:
            points = self._points(inputs, 'the SDG view transform is guided '
                                  'by LiDAR depth')
            time_dims = [s.metainfo.get('points_time_dim')
                         for s in data_samples]
        return self.camera_bev(imgs, lidar2img, cam_params, points,
                               time_dims)

    def extract_camera_bev(self, inputs: dict, data_samples: Sequence
                           ) -> Tuple[Dict[str, Tensor], Dict[str, Tensor]]:
        """DepthNet outputs and the camera BEV the rest of the model sees.

        With T = 1, :meth:`frame_camera_bev`. With T > 1, ``imgs`` is
        Shape (B, T * N, 3, H, W) (current frame first); the current
        frame's BEV, and those of the T - 1 previous frames (from the test
        cache where it has them) warped into the current frame, are fused by
        ``temporal_fusion``. ``bev_current`` keeps the current frame's own
        BEV; ``bev_mask`` stays the current frame's pooled coverage (FOAD's
        M_img: a cell only earlier frames saw is still one the current
        cameras miss, so FOAD keeps distilling there).

        Returns:
            tuple[dict, dict]: As :meth:`frame_camera_bev`; the DepthNet
            outputs are the current frame's.
        """
        if self.num_frames == 1:
            return self.frame_camera_bev(inputs, data_samples)
        imgs = inputs['imgs']
        if imgs.dim() != 5 or imgs.shape[1] % self.num_frames:
            raise ValueError(f'SDGOcc(num_frames={self.num_frames}) expects '
                             'inputs["imgs"] of shape (B, T * N, 3, H, W), '
                             f'got {tuple(imgs.shape)}')
        views = self.lidar2img(data_samples, imgs.device).shape[1]
        if imgs.shape[1] != self.num_frames * views:
            raise ValueError(
                f'SDGOcc(num_frames={self.num_frames}): inputs["imgs"] holds '
                f'{imgs.shape[1]} views, expected T * N = {self.num_frames} '
                f'* {views} (the current frame\'s views, then each previous '
                "frame's, as LoadPreviousKeyFrames stacks them)")
        frames = imgs.unflatten(1, (self.num_frames, -1))
        depth_out, cam = self.frame_camera_bev(
            dict(inputs, imgs=frames[:, 0]), data_samples)
        use_cache = self.test_cache and not self.training
        if use_cache:
            self.bev_cache.put(
                [s.metainfo.get('token') for s in data_samples], cam['bev'])
        previous = []
        for k in range(1, self.num_frames):
            bev = None
            if use_cache:
                # A sample without the link misses; frame_samples then
                # says what the pipeline lacks.
                bev = self.bev_cache.get([
                    (s.metainfo.get('prev_tokens') or [None] * k)[k - 1]
                    for s in data_samples
                ])
            if bev is None:
                bev = self._previous_camera_bev(frames[:, k], data_samples,
                                                k)
            previous.append(bev)
        cam['bev_current'] = cam['bev']
        cam['bev'] = self.temporal_fusion(
            cam['bev'], previous,
            self.stack_meta(data_samples, 'prev2curr', imgs.device),
            self.point_cloud_range)
        return depth_out, cam

    def _previous_camera_bev(self, imgs: Tensor, data_samples: Sequence,
                             k: int) -> Tensor:
        """Camera BEV (B, C, Y, X) of frame t-k in its own frame.

        Without gradient, as BEVDet4D computes its adjacent frames: the
        current frame trains the shared camera branch, the previous ones
        only feed the fusion conv, and the test cache (which stores
        detached BEVs) then sees exactly what training saw.
        """
        samples = frame_samples(data_samples, k)
        inputs = dict(imgs=imgs)
        if self.view_transform.use_sdg:
            inputs['points'] = frame_points(data_samples, k, imgs.device)
        with torch.no_grad():
            return self.frame_camera_bev(inputs, samples)[1]['bev']

    def train(self, mode: bool = True) -> 'SDGOcc':
        """Switch mode; the test cache is emptied, as weights may change."""
        self.bev_cache.clear()
        return super().train(mode)

    @staticmethod
    def _points(inputs: dict, why: str) -> List[Tensor]:
        if 'points' not in inputs:
            raise ValueError(f'SDGOcc needs inputs["points"]: {why}')
        return list(inputs['points'])

    def extract_lidar_bev(self, inputs: dict) -> Dict[str, Tensor]:
        """LiDAR BEV ``bev`` (B, C, Y, X) and ``bev_mask`` (B, 1, Y, X)."""
        return self.lidar_encoder(
            self._points(inputs, 'the LiDAR encoder encodes them'))

    def fuse(self, lidar: Dict[str, Tensor], cam: Dict[str, Tensor]
             ) -> Tensor:
        """SDG-Fusion: camera queries, LiDAR keys and values; SDG-KL's
        teacher: LiDAR queries, camera keys and values (Sec. 3.5)."""
        if lidar['bev'].shape[-2:] != cam['bev'].shape[-2:]:
            raise ValueError(f'SDGOcc: LiDAR BEV {tuple(lidar["bev"].shape)}'
                             f' and camera BEV {tuple(cam["bev"].shape)} '
                             'are not on the same grid')
        if self.variant == 'fusion':
            return self.fusion(cam['bev'], lidar['bev'])
        return self.fusion(lidar['bev'], cam['bev'])

    def extract_feat(self, inputs: dict, data_samples: Sequence) -> Tensor:
        """The BEV the head sees at inference. Shape (B, C, Y, X)."""
        _, cam = self.extract_camera_bev(inputs, data_samples)
        if self.variant != 'fusion':
            # The camera rows and SDG-KL's inference: no LiDAR encoder, no
            # fusion.
            return cam['bev']
        return self.fuse(self.extract_lidar_bev(inputs), cam)

    # ------------------------------------------------------------------
    # mmengine contract
    # ------------------------------------------------------------------
    def _aux_losses(self, depth_out: Dict[str, Tensor],
                    data_samples: Sequence, device) -> Dict[str, Tensor]:
        """Depth and 2D semantic losses of the DepthNet."""
        losses = {}
        if self.loss_depth is None and self.loss_seg is None:
            return losses
        gt_depth = self.gt_depth(data_samples, device)
        losses.update(self.depth_losses(depth_out['depth'], gt_depth))
        losses.update(
            self.seg_losses(depth_out, data_samples, gt_depth,
                            self.downsample))
        return losses

    def loss(self, inputs: dict, data_samples: Sequence) -> Dict[str, Tensor]:
        """Training losses.

        Args:
            inputs (dict): ``imgs`` (B, N, 3, H, W), ``points`` (unless the
                variant is ``'camera'`` with the plain LSS lift).
            data_samples (Sequence[Det3DDataSample]): With ``gt_occ`` (X, Y,
                Z), the ``loss_mask_key`` mask if set, ``gt_depth`` and
                ``gt_seg_2d`` (N, H, W), and the camera metainfo.

        Returns:
            dict[str, Tensor]: Occupancy losses (for SDG-KL: of the fused
            BEV with ``kl_losses='paper'``, of the camera BEV plus
            ``*_teacher`` with ``'three_loss'``), ``loss_distill`` for
            SDG-KL, ``loss_depth``, ``loss_seg``, ``loss_point_seg``.
        """
        device = inputs['imgs'].device
        depth_out, cam = self.extract_camera_bev(inputs, data_samples)
        gt_occ = self.occupancy_targets(data_samples, device)
        losses = self._aux_losses(depth_out, data_samples, device)
        if self.variant == 'camera':
            losses.update(
                self.occ_head.loss(self.bev_encoder(cam['bev']), gt_occ))
            return losses
        lidar = self.extract_lidar_bev(inputs)
        if self.point_seg_head is not None:
            labels = gather_point_labels(data_samples, inputs['points'])
            losses.update(
                self.point_seg_head.loss(lidar['point_feats'],
                                         labels[lidar['point_index']]))
        if self.detach_teacher_camera:  # 'kl' only (checked at build)
            fused = self.fuse(lidar, dict(cam, bev=cam['bev'].detach()))
        else:
            fused = self.fuse(lidar, cam)
        if self.variant == 'fusion' or self.kl_losses == 'paper':
            # SDG-KL's 'paper' form: the one classification loss is the
            # fused BEV's, through the head the camera BEV meets at
            # inference.
            losses.update(self.occ_head.loss(self.bev_encoder(fused), gt_occ))
        else:
            losses.update(
                self.occ_head.loss(self.bev_encoder(cam['bev']), gt_occ))
            teacher_encoder, teacher_head = self._teacher_decoder()
            teacher = teacher_head.loss(
                teacher_encoder(fused), gt_occ, suffix='_teacher')
            losses.update({
                key: value * self.teacher_loss_weight
                for key, value in teacher.items()
            })
        if self.variant == 'fusion':
            return losses
        # The teacher's region is where the LiDAR identified something (the
        # "LiDAR-identified regions" of FOAD), not the whole fused map; the
        # camera region is the pooled coverage, the student the BEV after
        # camera_bev_conv (see __init__).
        losses['loss_distill'] = self.loss_distill(
            cam['bev'], fused, lidar['bev_mask'], cam['bev_mask'])
        return losses

    def predict(self, inputs: dict, data_samples: Sequence) -> list:
        """Occupancy of every sample.

        Args:
            inputs (dict): ``imgs`` (B, N, 3, H, W); ``points`` for the SDG
                lift and for SDG-Fusion's LiDAR encoder (the camera-only
                LSS baseline runs without them).
            data_samples (Sequence[Det3DDataSample]): Camera metainfo.

        Returns:
            list[Det3DDataSample]: The input samples with ``pred_occ`` (X, Y,
            Z) long added; their ground truth stays for the metric.
        """
        if self.predict_branch == 'teacher':
            _, cam = self.extract_camera_bev(inputs, data_samples)
            encoder, head = self._teacher_decoder()
            fused = self.fuse(self.extract_lidar_bev(inputs), cam)
            return self.add_pred_occ(data_samples,
                                     head.predict(encoder(fused)))
        return self.add_pred_occ(
            data_samples,
            self.decode(self.extract_feat(inputs, data_samples),
                        with_logits=False)[1])

    def decode(self, bev: Tensor, with_logits: bool = True
               ) -> Tuple[Optional[Tensor], Tensor]:
        """Occupancy of the BEV the head sees: BEV encoder and
        channel-to-height head, on tensors (shared with the ONNX graphs).

        Args:
            bev (Tensor): Shape (B, C, Y, X).
            with_logits (bool): Also return the logits. Defaults to True.

        Returns:
            tuple: Logits (B, num_classes, X, Y, Z), or None without
            ``with_logits``, and labels, int64 (B, X, Y, Z).
        """
        return self.occ_head.decode(self.bev_encoder(bev), with_logits)

    def _teacher_decoder(self) -> tuple:
        """SDG-KL teacher's BEV encoder and head (the student's unless
        ``separate_teacher_head``)."""
        if self.teacher_occ_head is not None:
            return self.teacher_bev_encoder, self.teacher_occ_head
        return self.bev_encoder, self.occ_head

    def _forward(self, inputs: dict, data_samples: Sequence) -> Tensor:
        """Occupancy logits (B, num_classes, X, Y, Z) of the inference path.
        """
        if self.predict_branch == 'teacher':
            raise ValueError("SDGOcc: predict_branch='teacher' scores the "
                             'teacher through predict (tools/test.py); the '
                             'inference path (tensor mode, export) is the '
                             "student's")
        return self.decode(self.extract_feat(inputs, data_samples))[0]
