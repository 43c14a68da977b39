"""An mmengine visualiser that draws occupancy data samples.

mmdet3d's ``tools/misc/browse_dataset.py`` builds ``cfg.visualizer``, sets
its ``dataset_meta`` and calls ``add_datasample(name, inputs,
data_sample=..., show=..., wait_time=..., out_file=..., o3d_save_path=...,
vis_task=...)`` for every packed training sample; the Runner builds the
same visualiser for ``OccVisualizationHook`` and the scalar logs. The
picture is :func:`~.sample_figure.render_data_sample`'s (GT, prediction,
error map; top-down and 3D; the cameras with the occupancy projected onto
them), whatever ``vis_task`` is: an occupancy sample has one picture.
"""
from typing import Optional, Sequence

import numpy as np
from mmdet3d.registry import VISUALIZERS
from mmengine.visualization import Visualizer

from ..datasets.occ_formats import OCC_FORMATS
from .occ_figure import save_png
from .palette import convention_classes
from .sample_figure import render_data_sample


@VISUALIZERS.register_module()
class OccLocalVisualizer(Visualizer):
    """Draw occupancy data samples; images go to files or the backends.

    The class names and the empty label come from ``dataset_meta``
    (``classes`` and ``occ_format``, as ``NuScenesOccDataset`` has them),
    else from ``convention``.

    Args:
        name (str): Instance name (mmengine's ``ManagerMixin``). Defaults
            to 'occ_visualizer'.
        vis_backends (list[dict], optional): mmengine visualisation
            backends (``LocalVisBackend``, ``TensorboardVisBackend``, ...).
            Defaults to None.
        save_dir (str, optional): Backend folder (the Runner passes its log
            dir). Defaults to None.
        convention (str): ``'surroundocc'`` or ``'occ3d'`` when the dataset
            meta does not say. Defaults to 'surroundocc'.
        draw_cameras (bool): Add the camera images of ``inputs['img']``.
            Defaults to True.
        view_size (Sequence[int]): ``(H, W)`` of the 3D views. Defaults to
            (360, 480).
    """

    def __init__(self,
                 name: str = 'occ_visualizer',
                 vis_backends: Optional[list] = None,
                 save_dir: Optional[str] = None,
                 convention: str = 'surroundocc',
                 draw_cameras: bool = True,
                 view_size: Sequence[int] = (360, 480)) -> None:
        convention_classes(convention)  # validates the name
        super().__init__(
            name=name, vis_backends=vis_backends, save_dir=save_dir)
        self.convention = convention
        self.draw_cameras = draw_cameras
        self.view_size = tuple(view_size)

    @classmethod
    def get_instance(cls, name: str = 'occ_visualizer', **kwargs):
        """mmengine's ``get_instance`` with a default ``name``.

        mmdet3d's browse_dataset builds ``cfg.visualizer`` without a name;
        the configs leave it out so that the Runner names each run's
        visualiser after the run (one shared name would hand a second
        Runner in the same process the first one's ``save_dir``).
        """
        return super().get_instance(name, **kwargs)

    def _classes(self):
        """Class names and empty label (see the class docstring)."""
        meta = self.dataset_meta or {}
        fmt = meta.get('occ_format')
        if fmt in OCC_FORMATS:
            default_names = OCC_FORMATS[fmt].class_names
            empty = OCC_FORMATS[fmt].empty_label
        else:
            default_names, empty = convention_classes(self.convention)
        return tuple(meta.get('classes') or default_names), empty

    def add_datasample(self,
                       name: str,
                       data_input: Optional[dict] = None,
                       data_sample=None,
                       draw_gt: bool = True,
                       draw_pred: bool = True,
                       show: bool = False,
                       wait_time: float = 0.,
                       out_file: Optional[str] = None,
                       step: int = 0,
                       **kwargs) -> np.ndarray:
        """Draw one sample; write it to ``out_file`` or the backends.

        Args:
            name (str): Image name for the backends.
            data_input (dict, optional): The packed inputs; ``img``
                (N, 3, H, W, BGR) is drawn with the occupancy projected
                onto it when ``draw_cameras``. Defaults to None.
            data_sample (Det3DDataSample | dict): With ``gt_occ`` and / or
                ``pred_occ`` (Shape (X, Y, Z)) and the packed metainfo.
            draw_gt (bool): Draw ``gt_occ``. Defaults to True.
            draw_pred (bool): Draw ``pred_occ``. Defaults to True.
            show (bool): Also show it in a window (needs a display).
                Defaults to False.
            wait_time (float): Seconds a shown picture stays. Defaults to 0.
            out_file (str, optional): PNG / JPEG file to write; without it
                the picture goes to the backends. Defaults to None.
            step (int): Backend step. Defaults to 0.
            **kwargs: browse_dataset's ``o3d_save_path`` and ``vis_task``;
                unused (no point-cloud window, one kind of picture).

        Returns:
            np.ndarray: The picture, Shape (H, W, 3), uint8.
        """
        if data_sample is None:
            raise ValueError(f'OccLocalVisualizer: {name} has no data '
                             'sample to draw.')
        names, empty = self._classes()
        img = None
        if self.draw_cameras and isinstance(data_input, dict):
            img = data_input.get('img')
        picture = render_data_sample(
            data_sample,
            names,
            empty,
            img=img,
            draw_gt=draw_gt,
            draw_pred=draw_pred,
            view_size=self.view_size)
        if show:
            self.show(picture, win_name=name, wait_time=wait_time)
        if out_file is not None:
            save_png(picture, out_file)
        else:
            self.add_image(name, picture, step)
        return picture
