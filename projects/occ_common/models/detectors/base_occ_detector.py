"""The contract both occupancy detectors share (OccCylindrical, SDG-OCC).

:class:`BaseOccDetector` owns what is the same in every camera + LiDAR
occupancy model of this library, so that it is written once:

* the occupancy task: the grid (``point_cloud_range``, ``voxel_size``), the
  classes (``num_classes``, ``empty_index``, ``ignore_index``) and the
  supervision mask (``loss_mask_key``). A subclass hands them to the
  children that need them (see :meth:`BaseOccDetector.head_defaults`), so a
  config states them once, at the top of ``model``;
* the depth bins (``depth_bound``), the LiDAR depth loss ``loss_depth``
  and the DepthNet's optional 2-D semantic loss ``loss_seg``;
* reading the data samples: stacked metainfo matrices, camera parameters,
  ground-truth fields and the occupancy targets, masked in one place;
* pretrained weights of its parts (``pretrained``), loaded and checked by
  :mod:`projects.occ_common.models.pretrained` after the initialisation.
"""
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
import torch.nn.functional as F
from mmdet3d.models.detectors import Base3DDetector
from mmdet3d.registry import MODELS
from mmdet3d.structures import Det3DDataSample
from mmdet3d.utils import OptConfigType, OptMultiConfig
from torch import Tensor, nn

from ...geometry.depth import normalize_depth_bound, num_depth_bins
from ...geometry.seg_targets import downsample_seg_labels
from ...utils.precision import float32_math
from ..layers.camera_geometry import camera_parameter_vector, lidar2img_matrix
from ..pretrained import check_entries, load_pretrained

#: Metainfo keys whose product is ``lidar2img`` (see camera_geometry).
CAMERA_KEYS = ('cam2img', 'lidar2cam', 'img_aug_matrix')


class BaseOccDetector(Base3DDetector):
    """Shared base of the occupancy detectors (not registered).

    Args:
        point_cloud_range (Sequence[float]): ``(x0, y0, z0, x1, y1, z1)`` of
            the occupancy grid in the working frame, metres.
        voxel_size (Sequence[float]): Voxel edge per axis, metres.
        num_classes (int): Occupancy classes, empty included.
        empty_index (int): Label of empty space (0 for SurroundOcc, 17 for
            Occ3D). Defaults to 0.
        ignore_index (int): Label of unsupervised voxels. Defaults to 255.
        loss_mask_key (str, optional): Data-sample field of a bool mask
            outside which voxels are not supervised (``'mask_camera'`` for
            Occ3D). Defaults to None.
        depth_bound (Sequence[float], optional): ``(min, max, step)`` of the
            depth bins, metres; given to ``loss_depth`` and, by subclasses,
            to every module that lifts or predicts depth. Defaults to None.
        loss_depth (dict, optional): Depth loss (``DepthBCELoss``); None
            removes the depth supervision. Defaults to None.
        loss_seg (dict, optional): 2-D semantic loss of the DepthNet's
            ``seg_logits`` on (N, C) logits and (N,) labels, e.g.
            ``mmdet.CrossEntropyLoss`` with ``ignore_index=255``; its
            targets are the LiDAR's projected lidarseg labels
            (``gt_seg_2d``, see :meth:`seg_targets`). Defaults to None.
        seg_empty_label (int, optional): 2-D semantic target of feature
            cells that no labelled LiDAR return hits; None (the default)
            leaves them unsupervised (label 255).
        pretrained (dict, optional): Entry name -> where and what to load
            (``module`` path, ``checkpoint``, ...; see
            :mod:`projects.occ_common.models.pretrained`), applied by
            :meth:`init_weights`. Defaults to None (nothing).
        data_preprocessor (dict, optional): ``Det3DDataPreprocessor``
            config. Defaults to None.
        init_cfg (dict, optional): Initialisation config. Defaults to None.
    """

    def __init__(self,
                 point_cloud_range: Sequence[float],
                 voxel_size: Sequence[float],
                 num_classes: int,
                 empty_index: int = 0,
                 ignore_index: int = 255,
                 loss_mask_key: Optional[str] = None,
                 depth_bound: Optional[Sequence[float]] = None,
                 loss_depth: OptConfigType = None,
                 loss_seg: OptConfigType = None,
                 seg_empty_label: Optional[int] = None,
                 pretrained: Optional[dict] = None,
                 data_preprocessor: OptConfigType = None,
                 init_cfg: OptMultiConfig = None) -> None:
        super().__init__(
            data_preprocessor=data_preprocessor, init_cfg=init_cfg)
        name = type(self).__name__
        self.pretrained = check_entries(pretrained)
        if len(point_cloud_range) != 6 or len(voxel_size) != 3:
            raise ValueError(f'{name}: point_cloud_range needs 6 values and '
                             f'voxel_size 3, got {point_cloud_range} and '
                             f'{voxel_size}')
        self.point_cloud_range = tuple(float(v) for v in point_cloud_range)
        self.voxel_size = tuple(float(v) for v in voxel_size)
        #: (X, Y, Z) voxels of the occupancy grid.
        self.occ_shape = tuple(
            round((self.point_cloud_range[i + 3] - self.point_cloud_range[i])
                  / self.voxel_size[i]) for i in range(3))
        if min(self.occ_shape) < 1:
            raise ValueError(f'{name}: point_cloud_range {point_cloud_range}'
                             f' and voxel_size {voxel_size} give the grid '
                             f'{self.occ_shape}')
        if not 0 <= empty_index < num_classes:
            raise ValueError(f'{name}: empty_index {empty_index} is not one '
                             f'of the {num_classes} classes')
        self.num_classes = num_classes
        self.empty_index = empty_index
        self.ignore_index = ignore_index
        self.loss_mask_key = loss_mask_key
        self.depth_bound = None
        if depth_bound is not None:
            num_depth_bins(depth_bound)  # validates
            self.depth_bound = normalize_depth_bound(depth_bound)
        self.loss_depth = self.build_child(loss_depth,
                                           depth_bound=self.depth_bound)
        self.loss_seg = self.build_child(loss_seg)
        self.seg_empty_label = seg_empty_label

    def init_weights(self) -> None:
        """Initialise every part, then load the ``pretrained`` entries.

        The entries load last so that no child's own initialisation
        overwrites them; an entry without a checkpoint only checks that its
        part trains normally (nothing frozen).

        Raises:
            ValueError: For an entry whose ``module`` is not a part of this
                detector, and from
                :func:`~projects.occ_common.models.pretrained.load_pretrained`.
        """
        super().init_weights()
        for name, entry in self.pretrained.items():
            try:
                part = self.get_submodule(entry['module'])
            except AttributeError as err:
                raise ValueError(
                    f'{type(self).__name__}: pretrained.{name} names module '
                    f'{entry["module"]!r}, which this model does not have'
                ) from err
            load_pretrained(part, name, entry, self.data_preprocessor)

    # ------------------------------------------------------------------
    # Building children from the shared values
    # ------------------------------------------------------------------
    @staticmethod
    def build_child(cfg: OptConfigType, **defaults) -> Optional[nn.Module]:
        """Build a child, giving it the shared values its config omits.

        Args:
            cfg (dict, optional): The child's config; None builds nothing.
            **defaults: Values set where the config has no such key; a key
                whose value is None is not set.

        Returns:
            nn.Module | None: The child.
        """
        if not cfg:
            return None
        return MODELS.build(
            cfg,
            default_args={k: v
                          for k, v in defaults.items() if v is not None})

    def head_defaults(self) -> Dict:
        """Classes and labels every occupancy head takes from the detector.

        Returns:
            dict: ``num_classes``, ``empty_index`` and ``ignore_index``; the
            head passes the labels on to its ``loss_occ``.
        """
        return dict(
            num_classes=self.num_classes,
            empty_index=self.empty_index,
            ignore_index=self.ignore_index)

    def check_child(self, child: nn.Module, **expected) -> None:
        """Refuse a child configured against the detector's shared values.

        Args:
            child (nn.Module): A built child.
            **expected: Attribute name -> the detector's value (values
                that are None are not checked).

        Raises:
            ValueError: Naming the child, the attribute and both values.
        """
        for attr, value in expected.items():
            got = getattr(child, attr, None)
            if value is None or got is None:
                continue
            if isinstance(value, (tuple, list)):
                got, value = tuple(got), tuple(value)
            if got != value:
                raise ValueError(
                    f'{type(self).__name__}: {type(child).__name__} has '
                    f'{attr}={got} but the detector has {attr}={value}; '
                    'set it once, on the detector')

    # ------------------------------------------------------------------
    # Reading the data samples
    # ------------------------------------------------------------------
    def _sample_name(self, sample: Det3DDataSample, index: int) -> str:
        return (f'{type(self).__name__}: data sample '
                f'{sample.metainfo.get("sample_idx", index)}')

    def stack_meta(self, samples: Sequence[Det3DDataSample], key: str,
                   device: torch.device) -> Tensor:
        """Stack a per-sample metainfo array into one float32 tensor.

        Args:
            samples (Sequence[Det3DDataSample]): The batch.
            key (str): Metainfo key, e.g. ``'lidar2img'``.
            device (torch.device): Device of the result.

        Returns:
            Tensor: Shape (B, ...), the per-sample shape.
        """
        values = []
        for i, sample in enumerate(samples):
            if key not in sample.metainfo:
                raise ValueError(f'{self._sample_name(sample, i)} has no '
                                 f'metainfo {key!r}')
            values.append(torch.as_tensor(np.asarray(sample.metainfo[key])))
        return torch.stack(values).to(device=device, dtype=torch.float32)

    def stack_field(self, samples: Sequence[Det3DDataSample], key: str,
                    device: torch.device) -> Tensor:
        """Stack a per-sample ground-truth field (``gt_occ``, ...).

        Args:
            samples (Sequence[Det3DDataSample]): The batch.
            key (str): Data-sample field; the pipeline must pack it.
            device (torch.device): Device of the result.

        Returns:
            Tensor: Shape (B, ...), the field's dtype.
        """
        values = []
        for i, sample in enumerate(samples):
            if key not in sample:
                raise ValueError(f'{self._sample_name(sample, i)} has no '
                                 f'{key!r} (the pipeline must pack it)')
            values.append(torch.as_tensor(sample.get(key)))
        return torch.stack(values).to(device)

    def lidar2img(self, samples: Sequence[Det3DDataSample],
                  device: torch.device) -> Tensor:
        """Full projection of every view: the metainfo ``lidar2img``, or
        ``img_aug_matrix @ cam2img @ lidar2cam``. Shape (B, N, 4, 4)."""
        if all('lidar2img' in s.metainfo for s in samples):
            return self.stack_meta(samples, 'lidar2img', device)
        return lidar2img_matrix(
            *(self.stack_meta(samples, key, device) for key in CAMERA_KEYS))

    def camera_params(self, samples: Sequence[Det3DDataSample],
                      device: torch.device) -> Tensor:
        """BEVDepth's camera parameters of every view. Shape (B * N, 22)."""
        return camera_parameter_vector(
            *(self.stack_meta(samples, key, device)
              for key in CAMERA_KEYS)).flatten(0, 1)

    def occupancy_targets(self, samples: Sequence[Det3DDataSample],
                          device: torch.device) -> Tensor:
        """Occupancy labels, ``ignore_index`` outside ``loss_mask_key``.

        Args:
            samples (Sequence[Det3DDataSample]): With ``gt_occ``
                Shape (X, Y, Z) and, when ``loss_mask_key`` is set, that
                bool mask of the same shape.
            device (torch.device): Device of the result.

        Returns:
            Tensor: Long labels. Shape (B, X, Y, Z).
        """
        gt_occ = self.stack_field(samples, 'gt_occ', device).long()
        if tuple(gt_occ.shape[1:]) != self.occ_shape:
            raise ValueError(f'{type(self).__name__}: gt_occ of shape '
                             f'{tuple(gt_occ.shape[1:])} does not match the '
                             f'grid {self.occ_shape} of point_cloud_range '
                             'and voxel_size')
        if self.loss_mask_key is None:
            return gt_occ
        mask = self.stack_field(samples, self.loss_mask_key, device)
        if mask.shape != gt_occ.shape:
            raise ValueError(f'{type(self).__name__}: {self.loss_mask_key} '
                             f'{tuple(mask.shape)} does not match gt_occ '
                             f'{tuple(gt_occ.shape)}')
        return gt_occ.masked_fill(~mask.bool(), self.ignore_index)

    def gt_depth(self, samples: Sequence[Det3DDataSample],
                 device: torch.device,
                 input_shape: Optional[Tuple[int, int]] = None) -> Tensor:
        """LiDAR depth maps of every view, 0 where no return.

        Args:
            samples (Sequence[Det3DDataSample]): With ``gt_depth``
                Shape (N, H, W).
            device (torch.device): Device of the result.
            input_shape (tuple[int, int], optional): Padded network input
                ``(H_in, W_in)``; the maps are padded at the bottom and
                right to it (padded pixels have no return, like the
                padded images). Defaults to None (no padding).

        Returns:
            Tensor: Float depth. Shape (B * N, H_in, W_in).
        """
        depth = self.stack_field(samples, 'gt_depth', device).float()
        if input_shape is not None:
            pad_h = input_shape[0] - depth.shape[-2]
            pad_w = input_shape[1] - depth.shape[-1]
            if pad_h < 0 or pad_w < 0:
                raise ValueError(f'{type(self).__name__}: gt_depth '
                                 f'{tuple(depth.shape)} is larger than the '
                                 f'input images {tuple(input_shape)}')
            depth = F.pad(depth, (0, pad_w, 0, pad_h))
        return depth.flatten(0, 1)

    @float32_math
    def depth_losses(self, depth: Tensor, gt_depth: Tensor
                     ) -> Dict[str, Tensor]:
        """``loss_depth`` of the predicted depth bins, if configured.

        Args:
            depth (Tensor): Bin probabilities. Shape (B * N, D, h, w).
            gt_depth (Tensor): From :meth:`gt_depth`. Shape (B * N, H, W).

        Returns:
            dict[str, Tensor]: ``{'loss_depth': scalar}`` or empty.
        """
        if self.loss_depth is None:
            return {}
        return {'loss_depth': self.loss_depth(depth, gt_depth)}

    def seg_targets(self, samples: Sequence[Det3DDataSample],
                    gt_depth: Tensor, downsample: int) -> Tensor:
        """2-D semantic targets at feature resolution.

        The label of the nearest labelled LiDAR return of each feature cell
        (:func:`downsample_seg_labels`); cells without one get
        ``seg_empty_label`` (by default the ignore label 255).

        Args:
            samples (Sequence[Det3DDataSample]): With ``gt_seg_2d``
                Shape (N, H, W).
            gt_depth (Tensor): From :meth:`gt_depth`. Shape (B * N, H, W).
            downsample (int): Feature stride.

        Returns:
            Tensor: Long labels. Shape (B * N, H / s, W / s).
        """
        gt_seg = self.stack_field(samples, 'gt_seg_2d',
                                  gt_depth.device).flatten(0, 1)
        if gt_seg.shape != gt_depth.shape:
            # The depth maps are padded to the network input; so are the
            # labels, with the ignore label.
            pad_h = gt_depth.shape[-2] - gt_seg.shape[-2]
            pad_w = gt_depth.shape[-1] - gt_seg.shape[-1]
            gt_seg = F.pad(gt_seg, (0, pad_w, 0, pad_h), value=255)
        return downsample_seg_labels(
            gt_seg, gt_depth, downsample, empty_label=self.seg_empty_label)

    @float32_math
    def seg_losses(self, depth_out: Dict[str, Tensor],
                   samples: Sequence[Det3DDataSample], gt_depth: Tensor,
                   downsample: int) -> Dict[str, Tensor]:
        """``loss_seg`` of the DepthNet's semantic logits, if configured.

        Args:
            depth_out (dict[str, Tensor]): The DepthNet's outputs, with
                ``seg_logits`` Shape (B * N, C, h, w).
            samples (Sequence[Det3DDataSample]): With ``gt_seg_2d``.
            gt_depth (Tensor): From :meth:`gt_depth`. Shape (B * N, H, W).
            downsample (int): Feature stride (H / h).

        Returns:
            dict[str, Tensor]: ``{'loss_seg': scalar}`` or empty.

        Raises:
            ValueError: If ``loss_seg`` is set and the DepthNet has no
                semantic head.
        """
        if self.loss_seg is None:
            return {}
        if 'seg_logits' not in depth_out:
            raise ValueError(f'{type(self).__name__}: loss_seg needs a '
                             'DepthNet with seg_channels > 0')
        target = self.seg_targets(samples, gt_depth, downsample).reshape(-1)
        logits = depth_out['seg_logits']
        kwargs = {}
        if getattr(self.loss_seg, 'avg_non_ignore', False):
            # mmdet's CrossEntropyLoss(avg_non_ignore=True) would count the
            # labels that are not ignored with a host read (a sync, a graph
            # break under torch.compile); the same count, given as its
            # avg_factor, stays on the device.
            ignore = getattr(self.loss_seg, 'ignore_index', None)
            kwargs['avg_factor'] = (
                target != (-100 if ignore is None else ignore)).sum()
        return {
            'loss_seg':
            self.loss_seg(
                logits.permute(0, 2, 3, 1).reshape(-1, logits.shape[1]),
                target, **kwargs)
        }

    @staticmethod
    def add_pred_occ(samples: Sequence[Det3DDataSample],
                     pred_occ: Tensor) -> List[Det3DDataSample]:
        """Attach ``pred_occ`` Shape (X, Y, Z) to every sample.

        Their ``gt_occ`` and masks stay in place for the metric.
        """
        for sample, pred in zip(samples, pred_occ):
            sample.pred_occ = pred
        return list(samples)
