"""A toy occupancy dataset and model for tests of the training tools.

They exercise ``tools/train.py`` / ``tools/test.py``, checkpointing and
resuming in seconds, independently of the real models. They are registered
only when this module is imported (a test config lists it in
``custom_imports``), never by ``import projects.occ_common``.
"""
import os
import time
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np
import torch
from mmdet3d.registry import DATASETS, MODELS
from mmengine.dataset import BaseDataset
from mmengine.model import BaseModel
from mmengine.structures import BaseDataElement
from torch import Tensor, nn


@DATASETS.register_module()
class ToyOccupancyDataset(BaseDataset):
    """Random voxel grids whose class is readable from noisy features.

    Sample ``i`` has a label grid drawn with seed ``seed + i`` and features
    ``one_hot(label) + noise * randn``, so a 1x1x1 convolution can learn it.

    Args:
        num_samples (int): Number of samples. Defaults to 8.
        occ_shape (tuple[int]): ``(X, Y, Z)``. Defaults to (8, 8, 4).
        num_classes (int): Number of classes, 0 = empty. Defaults to 3.
        noise (float): Feature noise. Defaults to 0.5.
        seed (int): Base seed. Defaults to 0.
        ray_origins (Sequence[Sequence[float]], optional): RayIoU's ray
            origins (T, 3), metres, given to every sample as the metainfo
            ``ray_origins``. Defaults to None (none).
    """

    METAINFO = dict(classes=('empty', 'car', 'road'))

    def __init__(self,
                 num_samples: int = 8,
                 occ_shape: Tuple[int, int, int] = (8, 8, 4),
                 num_classes: int = 3,
                 noise: float = 0.5,
                 seed: int = 0,
                 ray_origins: Optional[Sequence[Sequence[float]]] = None,
                 **kwargs) -> None:
        self.num_samples = num_samples
        self.ray_origins = None if ray_origins is None else np.asarray(
            ray_origins, dtype=np.float64).reshape(-1, 3)
        self.occ_shape = tuple(occ_shape)
        self.num_classes = num_classes
        self.noise = noise
        self.seed = seed
        super().__init__(serialize_data=False, **kwargs)

    def load_data_list(self) -> List[dict]:
        """Generate every sample once, deterministically."""
        data_list = []
        for idx in range(self.num_samples):
            gen = torch.Generator().manual_seed(self.seed + idx)
            label = torch.randint(
                0, self.num_classes, self.occ_shape, generator=gen)
            feats = nn.functional.one_hot(label, self.num_classes).float()
            feats = feats + self.noise * torch.randn(
                feats.shape, generator=gen)
            data_list.append(
                dict(
                    sample_idx=idx,
                    inputs=feats.permute(3, 0, 1, 2).contiguous(),
                    gt_occ=label))
        return data_list

    def prepare_data(self, idx: int) -> dict:
        """Return ``dict(inputs, data_samples)`` as the pack transforms do."""
        info = self.get_data_info(idx)
        metainfo = dict(sample_idx=info['sample_idx'])
        if self.ray_origins is not None:
            metainfo['ray_origins'] = self.ray_origins
        sample = BaseDataElement(metainfo=metainfo)
        sample.gt_occ = info['gt_occ']
        return dict(inputs=info['inputs'], data_samples=sample)


def _cross_entropy(logits: Tensor, gt: Tensor) -> Tensor:
    """Mean cross-entropy over voxels, from deterministic kernels only.

    ``F.cross_entropy`` of a 5-D input runs ``nll_loss2d``, whose CUDA
    kernel raises under ``torch.use_deterministic_algorithms(True)``, which
    the resume tests ask for (``randomness.deterministic``); a log-softmax
    times a one-hot is elementwise, deterministic on every device and
    equal in value.

    Args:
        logits (Tensor): Shape (B, C, X, Y, Z).
        gt (Tensor): Class indices, Shape (B, X, Y, Z).

    Returns:
        Tensor: The mean over the B*X*Y*Z voxels, a scalar.
    """
    one_hot = nn.functional.one_hot(gt.long(), logits.shape[1])
    log_p = nn.functional.log_softmax(logits, dim=1)
    return -(log_p * one_hot.movedim(-1, 1)).sum(1).mean()


@MODELS.register_module()
class ToyOccupancyModel(BaseModel):
    """A 1x1x1 convolution classifying every voxel.

    Args:
        in_channels (int): Feature channels. Defaults to 3.
        num_classes (int): Number of classes. Defaults to 3.
        data_preprocessor (dict, optional): Defaults to None.
        init_cfg (dict, optional): Defaults to None.
        nan_at_iter (int, optional): Make the loss of this training
            iteration NaN (1-based, counting the ``mode='loss'`` calls of
            this process), to test the non-finite loss guard. Defaults to
            None (never).
        explode_at_iter (int, optional): Make the gradients of this
            training iteration infinite while its loss stays finite, so
            that the step explodes the weights (counted as
            ``nan_at_iter``). Defaults to None (never).
        dropout (float): Probability of ``Dropout3d`` on the inputs in
            training: random draws from torch's global generator, as
            DropPath's, to test that a resume repeats them. Defaults to 0
            (no dropout, nothing drawn).
        pause_at_iter (int, optional): Before this training iteration
            (counted as ``nan_at_iter``), wait until ``resume_file``
            exists, so that a test can act while a real run is known to
            be mid-training, however loaded the machine. Defaults to None
            (never).
        resume_file (str, optional): The file ``pause_at_iter`` waits
            for. Defaults to None.
    """

    #: Seconds a paused run waits for its ``resume_file`` before it fails.
    PAUSE_TIMEOUT = 600

    def __init__(self,
                 in_channels: int = 3,
                 num_classes: int = 3,
                 data_preprocessor: Optional[dict] = None,
                 init_cfg: Optional[dict] = None,
                 nan_at_iter: Optional[int] = None,
                 explode_at_iter: Optional[int] = None,
                 dropout: float = 0.,
                 pause_at_iter: Optional[int] = None,
                 resume_file: Optional[str] = None) -> None:
        super().__init__(
            data_preprocessor=data_preprocessor, init_cfg=init_cfg)
        self.dropout = nn.Dropout3d(dropout) if dropout > 0 else None
        self.classifier = nn.Conv3d(in_channels, num_classes, 1)
        self.nan_at_iter = nan_at_iter
        self.explode_at_iter = explode_at_iter
        if pause_at_iter is not None and resume_file is None:
            raise ValueError('pause_at_iter needs a resume_file to wait for')
        self.pause_at_iter = pause_at_iter
        self.resume_file = resume_file
        self._loss_calls = 0

    def _pause(self) -> None:
        """Wait for ``resume_file``; TimeoutError after PAUSE_TIMEOUT s."""
        deadline = time.monotonic() + self.PAUSE_TIMEOUT
        while not os.path.exists(self.resume_file):
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f'{self.resume_file} did not appear within '
                    f'{self.PAUSE_TIMEOUT} s of the pause at training '
                    f'iteration {self.pause_at_iter}')
            time.sleep(0.1)

    def forward(self,
                inputs: Union[Tensor, Sequence[Tensor]],
                data_samples: Optional[List[BaseDataElement]] = None,
                mode: str = 'tensor'):
        """Dispatch to ``loss`` / ``predict`` / ``_forward``.

        Args:
            inputs (Tensor | list[Tensor]): Shape (B, C, X, Y, Z), or a list
                of (C, X, Y, Z) as the default collate gives.
            data_samples (list[BaseDataElement], optional): Each with
                ``gt_occ`` Shape (X, Y, Z).
            mode (str): 'loss', 'predict' or 'tensor'.
        """
        if isinstance(inputs, (list, tuple)):
            inputs = torch.stack(list(inputs))
        if self.dropout is not None:
            inputs = self.dropout(inputs)
        logits = self.classifier(inputs)
        if mode == 'tensor':
            return logits
        if mode == 'loss':
            if self._loss_calls + 1 == self.pause_at_iter:
                self._pause()
            gt = torch.stack([s.gt_occ for s in data_samples])
            loss = _cross_entropy(logits, gt.to(logits.device))
            self._loss_calls += 1
            if self._loss_calls == self.nan_at_iter:
                loss = loss * float('nan')
            if self._loss_calls == self.explode_at_iter:
                logits.register_hook(lambda grad: grad * float('inf'))
            return dict(loss_ce=loss)
        if mode == 'predict':
            for sample, pred in zip(data_samples, logits.argmax(1)):
                sample.pred_occ = pred
            return data_samples
        raise RuntimeError(f'Invalid mode "{mode}"; expected loss, predict '
                           'or tensor.')
