"""Draw occupancy pictures of evaluated samples (``tools/test.py --show-dir``).

``configs/_base_/default_runtime.py`` lists this hook as
``default_hooks.visualization`` with ``draw=False``; ``tools/test.py
--show-dir DIR`` sets ``draw=True`` and ``test_out_dir=DIR``, and the hook
then writes ``{log_dir}/DIR/{sample}.png`` for every evaluated sample (an
absolute ``DIR`` is used as is), ``{sample}`` being
``<scene_name>_<token>`` (:func:`~projects.occ_common.visualization.
sample_name`): GT, prediction and error map, top-down and in 3D
(:func:`~projects.occ_common.visualization.render_data_sample`).
During validation, and in testing without ``test_out_dir``, the pictures
go to the Runner's visualiser backends (``vis_data/`` of the log dir with
mmengine's default ``LocalVisBackend``).

The seconds spent drawing a batch are logged as ``{mode}/vis_time``; they
are not part of ``data_time``: see :attr:`OccVisualizationHook.priority`.
"""
import os.path as osp
import time
from typing import Optional, Sequence

import numpy as np
from mmdet3d.registry import HOOKS
from mmengine.hooks import Hook

from ...visualization import (convention_classes, render_data_sample,
                              sample_name, save_png)


@HOOKS.register_module()
class OccVisualizationHook(Hook):
    """Write one picture per evaluated sample from ``pred_occ`` / ``gt_occ``.

    The class names and the label of empty space are, in this order: the
    arguments, the evaluator's ``OccupancyMetric`` (its ``class_names`` and
    ``empty_index``), or the dataset's ``classes`` with the ``convention``.

    Args:
        draw (bool): Draw at all. Defaults to False.
        interval (int): Draw every ``interval``-th sample of each rank.
            Defaults to 1 (all).
        show (bool): Not supported: the pictures are files, drawn without a
            display. Must be False.
        wait_time (float): Unused; accepted for ``tools/test.py --show``'s
            arguments. Defaults to 0.
        test_out_dir (str, optional): Folder of the test pictures, relative
            to the Runner's log dir. Defaults to None.
        draw_gt (bool): Draw the GT. Defaults to True.
        draw_pred (bool): Draw the prediction. Defaults to True.
        draw_cameras (bool): Add the camera images of ``inputs['img']``
            with the occupancy projected onto them. Defaults to False.
        bgr (bool): Whether those images are BGR (the loaders' order).
            Defaults to True.
        convention (str): ``'surroundocc'`` or ``'occ3d'``, used when no
            ``OccupancyMetric`` tells the empty label. Defaults to
            'surroundocc'.
        class_names (Sequence[str], optional): Defaults to None (see above).
        empty_label (int, optional): Defaults to None (see above).
        palette (Sequence, optional): RGB per class, Shape (C, 3). Defaults
            to the nuScenes colours by class name.
        ignore_index (int): GT label never drawn. Defaults to 255.
        use_mask (bool): Draw and count only ``mask_camera`` voxels when a
            sample has them. Defaults to True.
        view_size (Sequence[int]): ``(H, W)`` of the 3D views. Defaults to
            (360, 480).
    """

    #: mmengine's ``IterTimerHook`` (``NORMAL``) restarts its clock in
    #: ``after_*_iter`` and logs the time until the next ``before_*_iter``
    #: as ``data_time``. Drawing after it (a ``NORMAL`` hook registered
    #: later) put the drawing into the next batch's ``data_time``; drawing
    #: before it keeps ``data_time`` to loading and counts the drawing in
    #: the iteration's ``time`` (and so in the ETA), besides ``vis_time``.
    priority = 'ABOVE_NORMAL'

    def __init__(self,
                 draw: bool = False,
                 interval: int = 1,
                 show: bool = False,
                 wait_time: float = 0.,
                 test_out_dir: Optional[str] = None,
                 draw_gt: bool = True,
                 draw_pred: bool = True,
                 draw_cameras: bool = False,
                 bgr: bool = True,
                 convention: str = 'surroundocc',
                 class_names: Optional[Sequence[str]] = None,
                 empty_label: Optional[int] = None,
                 palette: Optional[Sequence] = None,
                 ignore_index: int = 255,
                 use_mask: bool = True,
                 view_size: Sequence[int] = (360, 480)) -> None:
        if show:
            raise ValueError(
                'OccVisualizationHook writes PNG files and opens no window: '
                'use tools/test.py --show-dir DIR instead of --show.')
        if interval < 1:
            raise ValueError('OccVisualizationHook: expected interval >= 1,'
                             f' got {interval}.')
        if not (draw_gt or draw_pred):
            raise ValueError('OccVisualizationHook: draw_gt and draw_pred '
                             'are both False; nothing to draw.')
        convention_classes(convention)  # validates the name
        self.draw = draw
        self.interval = interval
        self.wait_time = wait_time
        self.test_out_dir = test_out_dir
        self.draw_gt = draw_gt
        self.draw_pred = draw_pred
        self.draw_cameras = draw_cameras
        self.bgr = bgr
        self.convention = convention
        self.class_names = (tuple(class_names)
                            if class_names is not None else None)
        self.empty_label = empty_label
        self.palette = None if palette is None else np.asarray(palette)
        self.ignore_index = ignore_index
        self.use_mask = use_mask
        self.view_size = tuple(view_size)
        self._seen = {'val': 0, 'test': 0}
        self._out_dir: Optional[str] = None

    def _classes(self, runner, mode: str):
        """Class names and empty label (see the class docstring)."""
        names, empty = self.class_names, self.empty_label
        loop = runner.val_loop if mode == 'val' else runner.test_loop
        for metric in getattr(loop.evaluator, 'metrics', []):
            if hasattr(metric, 'class_names') and hasattr(
                    metric, 'empty_index'):
                names = names or tuple(metric.class_names)
                empty = metric.empty_index if empty is None else empty
                break
        if names is None:
            meta = getattr(loop.dataloader.dataset, 'metainfo', {}) or {}
            names = tuple(meta.get('classes') or ())
        default_names, default_empty = convention_classes(self.convention)
        names = names or default_names
        empty = default_empty if empty is None else empty
        return names, empty

    def before_val(self, runner) -> None:
        """Restart the per-rank sample count."""
        self._seen['val'] = 0

    def before_test(self, runner) -> None:
        """Restart the count and resolve the output folder."""
        self._seen['test'] = 0
        self._out_dir = None
        if self.draw and self.test_out_dir is not None:
            self._out_dir = osp.join(runner.log_dir, self.test_out_dir)
            runner.logger.info('OccVisualizationHook: writing a picture '
                               f'per sample to {self._out_dir}')

    def after_val_iter(self, runner, batch_idx: int, data_batch=None,
                       outputs: Optional[Sequence] = None) -> None:
        """Send pictures of this batch to the visualiser backends."""
        self._draw_batch(runner, 'val', data_batch, outputs)

    def after_test_iter(self, runner, batch_idx: int, data_batch=None,
                        outputs: Optional[Sequence] = None) -> None:
        """Write pictures of this batch (or send them to the backends)."""
        self._draw_batch(runner, 'test', data_batch, outputs)

    def _draw_batch(self, runner, mode: str, data_batch,
                    outputs: Optional[Sequence]) -> None:
        """Render every ``interval``-th sample of the batch and log the
        seconds it took as ``{mode}/vis_time``."""
        if not self.draw or not outputs:
            return
        start = time.perf_counter()
        names, empty = self._classes(runner, mode)
        images = self._batch_images(data_batch, len(outputs))
        for i, sample in enumerate(outputs):
            index = self._seen[mode]
            self._seen[mode] += 1
            if index % self.interval:
                continue
            picture = render_data_sample(
                sample,
                names,
                empty,
                palette=self.palette,
                ignore_index=self.ignore_index,
                img=images[i],
                bgr=self.bgr,
                draw_pred=self.draw_pred,
                draw_gt=self.draw_gt,
                use_mask=self.use_mask,
                view_size=self.view_size)
            name = sample_name(sample, f'{runner.rank}_{index}')
            if mode == 'test' and self._out_dir is not None:
                save_png(picture, osp.join(self._out_dir, f'{name}.png'))
            else:
                runner.visualizer.add_image(
                    f'{mode}_occ_{name}', picture, step=runner.iter)
        runner.message_hub.update_scalar(f'{mode}/vis_time',
                                         time.perf_counter() - start)

    def _batch_images(self, data_batch, size: int) -> list:
        """The packed camera images of each sample, or Nones."""
        if not self.draw_cameras or not isinstance(data_batch, dict):
            return [None] * size
        inputs = data_batch.get('inputs')
        if not isinstance(inputs, dict) or inputs.get('img') is None:
            return [None] * size
        return list(inputs['img'])
