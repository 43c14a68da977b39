"""One picture of a sample: GT, prediction and their errors, with a legend.

Columns are ground truth, prediction and the error map (those given);
rows are the top-down view (:mod:`.bev_view`) and the 3D view
(:mod:`.voxel_view`); the camera images with the occupancy projected onto
them (:mod:`.camera_overlay`) go on top when given. matplotlib draws the
layout through its Agg canvas, so no display is needed; it is imported when
a figure is drawn, not when the package is imported (registering the
plugin's modules must not pull in a plotting library).
"""
import os
import os.path as osp
import re
from typing import Dict, List, Optional, Sequence

import numpy as np
from PIL import Image

from .bev_view import render_bev
from .camera_overlay import overlay_on_cameras
from .error_map import error_counts, occupancy_errors
from .label_grid import as_label_grid, as_mask, occupied_voxels
from .palette import ERROR_NAMES, ERROR_PALETTE, resolve_palette
from .voxel_view import render_voxels

#: Cameras per row of the picture (nuScenes' six views as 2 x 3).
CAMERAS_PER_ROW = 3

#: Font size of the picture's title, in points.
TITLE_FONTSIZE = 11

#: Free space at each side of the title, in inches.
TITLE_MARGIN = 0.15

#: matplotlib's default margins of the panels (``figure.subplot.*``), in
#: fractions of the figure: kept in inches when a long title takes more
#: lines and the figure grows.
PANELS_TOP, PANELS_BOTTOM = 0.88, 0.11


def render_occ_figure(pred=None,
                      gt=None,
                      class_names: Sequence[str] = (),
                      palette: Optional[np.ndarray] = None,
                      empty_label: int = 0,
                      ignore_index: int = 255,
                      mask=None,
                      voxel_size: Sequence[float] = (1.0, 1.0, 1.0),
                      images: Optional[np.ndarray] = None,
                      lidar2img: Optional[np.ndarray] = None,
                      point_cloud_range: Optional[Sequence[float]] = None,
                      title: str = '',
                      view_size: Sequence[int] = (360, 480),
                      azimuth: float = -150.0,
                      elevation: float = 40.0,
                      dpi: int = 100,
                      forward: str = '+x') -> np.ndarray:
    """Render the picture of one sample.

    Args:
        pred (np.ndarray | Tensor, optional): Predicted labels. Shape
            (X, Y, Z).
        gt (np.ndarray | Tensor, optional): GT labels. Shape (X, Y, Z).
        class_names (Sequence[str]): Names in label order.
        palette (np.ndarray, optional): Shape (C, 3). Defaults to
            :func:`~.palette.class_palette`.
        empty_label (int): Label of empty space. Defaults to 0.
        ignore_index (int): GT label never drawn or counted. Defaults to
            255.
        mask (np.ndarray | Tensor, optional): Voxels that are drawn and
            counted (Occ3D's ``mask_camera``). Shape (X, Y, Z). Defaults
            to None (all).
        voxel_size (Sequence[float]): Metres per voxel. Defaults to cubes.
        images (np.ndarray, optional): RGB views, Shape (N, H, W, 3),
            uint8; needs ``lidar2img`` and ``point_cloud_range``. Defaults
            to None (no camera row).
        lidar2img (np.ndarray, optional): Shape (N, 4, 4).
        point_cloud_range (Sequence[float], optional): Grid extent.
        title (str): Printed above the panels. Defaults to ''.
        view_size (Sequence[int]): ``(H, W)`` of a 3D view. Defaults to
            (360, 480).
        azimuth (float): 3D view azimuth in degrees. Defaults to -150.
        elevation (float): 3D view elevation in degrees. Defaults to 40.
        dpi (int): Resolution of the picture. Defaults to 100.
        forward (str): Grid direction ahead of the car: up in the top-down
            views, the origin of ``azimuth`` (:mod:`.orientation`).
            Defaults to '+x' (the ego frame).

    Returns:
        np.ndarray: The picture, Shape (H, W, 3), uint8.

    Raises:
        ValueError: If neither ``pred`` nor ``gt`` is given, their shapes
            differ, a label is out of range, or ``images`` comes without
            its geometry.
    """
    if pred is None and gt is None:
        raise ValueError('render_occ_figure: expected pred and/or gt.')
    palette = resolve_palette(class_names, palette)
    grids = {}
    if gt is not None:
        grids['Ground truth'] = as_label_grid(gt, 'gt_occ')
    if pred is not None:
        grids['Prediction'] = as_label_grid(pred, 'pred_occ')
    shapes = {g.shape for g in grids.values()}
    if len(shapes) > 1:
        raise ValueError(f'pred_occ and gt_occ differ in shape: {shapes}.')
    shape = shapes.pop()
    mask = as_mask(mask, shape, 'mask_camera')
    panels = {
        key: (labels, palette, empty_label)
        for key, labels in grids.items()
    }
    heading = title
    if len(grids) == 2:
        codes = occupancy_errors(grids['Prediction'], grids['Ground truth'],
                                 len(palette), empty_label, ignore_index,
                                 mask)
        panels['Error'] = (codes, ERROR_PALETTE, 0)
        counts = ', '.join(f'{k} {v}' for k, v in error_counts(codes).items())
        heading = f'{title}   wrong voxels: {counts}'.strip()

    views = {}
    bev_scale = max(1, 320 // max(shape[:2]))
    for key, (labels, colours, empty) in panels.items():
        views[key] = (
            render_bev(labels, colours, empty, ignore_index, mask, bev_scale,
                       name=key, forward=forward),
            render_voxels(labels, colours, empty, ignore_index, mask,
                          voxel_size, view_size, azimuth, elevation,
                          name=key, forward=forward))
    cameras = None
    if images is not None:
        if lidar2img is None or point_cloud_range is None:
            raise ValueError('render_occ_figure: images need lidar2img and '
                             'point_cloud_range.')
        shown = grids.get('Prediction', grids.get('Ground truth'))
        cameras = overlay_on_cameras(images, shown, lidar2img,
                                     point_cloud_range, voxel_size, palette,
                                     empty_label, ignore_index, mask)
    legend = _legend(grids, palette, class_names, empty_label, ignore_index,
                     mask, with_errors='Error' in panels)
    return _compose(views, cameras, legend, heading, dpi)


def _legend(grids: Dict[str, np.ndarray], palette: np.ndarray,
            class_names: Sequence[str], empty_label: int, ignore_index: int,
            mask, with_errors: bool) -> list:
    """Patches of the classes drawn in any panel, then the error codes."""
    from matplotlib.patches import Patch
    present = set()
    for key, labels in grids.items():
        drawn = occupied_voxels(labels, len(palette), empty_label,
                                ignore_index, mask, key)
        present.update(np.unique(labels[drawn]).tolist())
    handles = [
        Patch(facecolor=palette[c] / 255, edgecolor='k', label=class_names[c])
        for c in sorted(present)
    ]
    if with_errors:
        handles += [
            Patch(facecolor=ERROR_PALETTE[code] / 255, edgecolor='k',
                  label=ERROR_NAMES[code])
            for code in range(1, len(ERROR_NAMES))
        ]
    return handles


def _wrap_title(text: str, width_px: float, renderer, font) -> List[str]:
    """``text`` broken into lines no wider than ``width_px``.

    Lines break between phrases first (at ``'   '`` and after ``', '``, so
    ``'false positive 3'`` stays together), then between words; a word
    wider than a line (a long file name) is cut between characters.

    Args:
        text (str): The title.
        width_px (float): Room of a line, in pixels of ``renderer``.
        renderer (RendererAgg): Measures the text.
        font (FontProperties): The title's font.

    Returns:
        list[str]: The lines, at least one.
    """

    def width(line: str) -> float:
        return renderer.get_text_width_height_descent(line, font, False)[0]

    def pack(pieces, cut) -> List[str]:
        """Greedy lines of ``(separator, piece)`` pairs; ``cut`` splits a
        piece too wide for a line into smaller pairs."""
        lines, line = [], ''
        for sep, piece in pieces:
            if line and width(line + sep + piece) <= width_px:
                line += sep + piece
                continue
            if line:
                lines.append(line)
            if cut is None or width(piece) <= width_px:
                line = piece
                continue
            *full, line = cut(piece)
            lines += full
        return lines + [line]

    def chars(word: str) -> List[str]:
        return pack([('', char) for char in word], None)

    def words(phrase: str) -> List[str]:
        return pack(re.findall(r'(\s*)(\S+)', phrase), chars)

    parts = re.split(r'(   |(?<=,) )', text)
    return pack([('', parts[0])] + list(zip(parts[1::2], parts[2::2])),
                words)


def _figure(views: Dict[str, tuple], cameras: Optional[np.ndarray],
            legend: list, heading: str, dpi: int):
    """Lay the rendered views out on a Figure with an Agg canvas.

    The title is wrapped onto as many lines as the figure's width needs
    (centred, one long line used to run past both sides of the picture),
    and the figure grows by the extra lines so the panels keep their size.

    Returns:
        matplotlib.figure.Figure: Drawn once; ``fig.texts[0]`` is the title
        when ``heading`` is not empty.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.font_manager import FontProperties
    columns = len(views)
    camera_rows = 0 if cameras is None else -(-len(cameras) //
                                              CAMERAS_PER_ROW)
    camera_height = 0.0
    if cameras is not None:
        aspect = cameras.shape[1] / cameras.shape[2]
        camera_height = camera_rows * 4.0 * columns / CAMERAS_PER_ROW * aspect
    width = 4.0 * columns + 2.2
    height = 7.0 + camera_height + 0.4
    fig = Figure(figsize=(width, height), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    lines = []
    if heading:
        font = FontProperties(size=TITLE_FONTSIZE)
        lines = _wrap_title(heading, (width - 2 * TITLE_MARGIN) * dpi,
                            canvas.get_renderer(), font)
    # matplotlib's line spacing is 1.2 font sizes; points -> inches.
    extra = max(len(lines) - 1, 0) * 1.2 * TITLE_FONTSIZE / 72
    fig.set_size_inches(width, height + extra)
    ratios = [camera_height] * bool(camera_rows) + [3.5, 3.5]
    grid = fig.add_gridspec(
        len(ratios), columns + 1, height_ratios=ratios,
        width_ratios=[4.0] * columns + [2.2],
        top=1 - ((1 - PANELS_TOP) * height + extra) / (height + extra),
        bottom=PANELS_BOTTOM * height / (height + extra))
    row0 = 0
    if cameras is not None:
        sub = grid[0, :columns].subgridspec(camera_rows, CAMERAS_PER_ROW)
        for i, image in enumerate(cameras):
            ax = fig.add_subplot(sub[i // CAMERAS_PER_ROW,
                                     i % CAMERAS_PER_ROW])
            ax.imshow(image)
            ax.set_axis_off()
        row0 = 1
    for col, (key, (bev, view3d)) in enumerate(views.items()):
        for row, (image, label) in enumerate(((bev, 'top-down'),
                                              (view3d, '3D'))):
            ax = fig.add_subplot(grid[row0 + row, col])
            ax.imshow(image, interpolation='nearest')
            ax.set_title(f'{key} ({label})', fontsize=10)
            ax.set_xticks([])
            ax.set_yticks([])
            # A frame shows the grid's extent in the top-down view.
            for spine in ax.spines.values():
                spine.set_visible(label == 'top-down')
                spine.set_edgecolor('0.7')
    legend_ax = fig.add_subplot(grid[row0:, columns])
    legend_ax.set_axis_off()
    if legend:
        legend_ax.legend(handles=legend, loc='center left', fontsize=9,
                         frameon=False)
    if lines:
        fig.suptitle('\n'.join(lines), fontsize=TITLE_FONTSIZE)
    canvas.draw()
    return fig


def _compose(views: Dict[str, tuple], cameras: Optional[np.ndarray],
             legend: list, heading: str, dpi: int) -> np.ndarray:
    """The picture of :func:`_figure`, Shape (H, W, 3), uint8."""
    fig = _figure(views, cameras, legend, heading, dpi)
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def save_png(image: np.ndarray, path: str) -> str:
    """Write an RGB image as PNG, creating the folder.

    Args:
        image (np.ndarray): Shape (H, W, 3), uint8.
        path (str): Output file.

    Returns:
        str: ``path``.
    """
    folder = osp.dirname(osp.abspath(path))
    os.makedirs(folder, exist_ok=True)
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(path)
    return path
