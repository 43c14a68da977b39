"""Class colours and the label conventions of the occupancy pictures.

Every picture colours a class by its name, so SurroundOcc (label 0 =
``empty``, 1-16 the nuScenes classes) and Occ3D (0 = ``others``, 1-16,
17 = ``free``) grids of the same scene look alike: the 16 nuScenes classes,
``others`` and ``free`` take the nuScenes-lidarseg challenge palette of
:data:`~projects.occ_common.datasets.nuscenes_classes.OCC_CLASS_PALETTE`;
names outside it (a toy dataset's ``road``) take a fixed fallback colour
chosen by their label, so a picture never depends on dictionary order.
"""
from typing import Dict, Optional, Sequence, Tuple, Union

import numpy as np

from ..datasets.nuscenes_classes import (OCC3D_CLASS_NAMES, OCC3D_FREE_LABEL,
                                         OCC_CLASS_NAMES, OCC_CLASS_PALETTE)

#: SurroundOcc's 17 labels: 0 is empty, then the 16 nuScenes classes.
SURROUNDOCC_CLASS_NAMES: Tuple[str, ...] = ('empty', ) + OCC_CLASS_NAMES

#: ``convention -> (class names, label drawn as empty space)``, as in
#: :class:`~projects.occ_common.evaluation.OccupancyMetric`.
CONVENTIONS: Dict[str, Tuple[Tuple[str, ...], int]] = {
    'surroundocc': (SURROUNDOCC_CLASS_NAMES, 0),
    'occ3d': (OCC3D_CLASS_NAMES, OCC3D_FREE_LABEL),
}

#: Colour of every Occ3D class name (``others``, the 16 classes, ``free``).
NAME_TO_COLOUR: Dict[str, Tuple[int, int, int]] = {
    name: tuple(int(v) for v in colour)
    for name, colour in zip(OCC3D_CLASS_NAMES, OCC_CLASS_PALETTE)
}

#: Colours of names outside :data:`NAME_TO_COLOUR`, picked by label modulo
#: their count; none of them is in the nuScenes palette.
FALLBACK_COLOURS: np.ndarray = np.array(
    [[31, 119, 180], [44, 160, 44], [148, 103, 189], [140, 86, 75],
     [227, 119, 194], [188, 189, 34], [23, 190, 207], [127, 127, 127]],
    dtype=np.uint8)

#: Background of the views (empty columns, pixels hit by no voxel).
BACKGROUND: Tuple[int, int, int] = (255, 255, 255)

#: Error codes of :func:`~.error_map.occupancy_errors`, their names and
#: colours: 0 is no error (never drawn); red, blue and magenta are far
#: from every class colour.
ERROR_NAMES: Tuple[str, ...] = ('correct', 'false positive',
                                'false negative', 'wrong class')
ERROR_PALETTE: np.ndarray = np.array(
    [[200, 200, 200], [230, 25, 75], [0, 130, 200], [240, 50, 230]],
    dtype=np.uint8)


def convention_classes(convention: str) -> Tuple[Tuple[str, ...], int]:
    """Class names and empty label of a benchmark convention.

    Args:
        convention (str): ``'surroundocc'`` or ``'occ3d'``.

    Returns:
        tuple[tuple[str], int]: The class names in label order and the
        label of empty space (0 for SurroundOcc, 17 = free for Occ3D).

    Raises:
        ValueError: For any other convention.
    """
    if convention not in CONVENTIONS:
        raise ValueError(f'Expected convention in {sorted(CONVENTIONS)}, '
                         f'got {convention!r}.')
    return CONVENTIONS[convention]


def class_palette(class_names: Sequence[str]) -> np.ndarray:
    """One RGB colour per class, by name.

    Args:
        class_names (Sequence[str]): Names in label order.

    Returns:
        np.ndarray: Shape (C, 3), uint8. A nuScenes / Occ3D name takes its
        challenge colour; any other name (``empty`` included) the fallback
        colour of its label.

    Raises:
        ValueError: If ``class_names`` is empty.
    """
    if len(class_names) == 0:
        raise ValueError('class_palette: expected at least one class name.')
    palette = np.empty((len(class_names), 3), dtype=np.uint8)
    for label, name in enumerate(class_names):
        if name in NAME_TO_COLOUR:
            palette[label] = NAME_TO_COLOUR[name]
        else:
            palette[label] = FALLBACK_COLOURS[label % len(FALLBACK_COLOURS)]
    return palette


def resolve_palette(class_names: Sequence[str],
                    palette: Optional[Union[Sequence, np.ndarray]] = None
                    ) -> np.ndarray:
    """Validate a user palette or build the default one.

    Args:
        class_names (Sequence[str]): Names in label order (``C`` of them).
        palette (array-like, optional): RGB colours 0-255, Shape (C, 3).
            Defaults to :func:`class_palette` of ``class_names``.

    Returns:
        np.ndarray: Shape (C, 3), uint8.

    Raises:
        ValueError: If ``palette`` is not (C, 3) with values in 0..255.
    """
    if palette is None:
        return class_palette(class_names)
    array = np.asarray(palette)
    if array.shape != (len(class_names), 3):
        raise ValueError(f'Expected a palette of shape ({len(class_names)}, '
                         f'3) for classes {tuple(class_names)}, got '
                         f'{array.shape}.')
    if array.size and (array.min() < 0 or array.max() > 255):
        raise ValueError('Expected palette values in 0..255, got '
                         f'{array.min()}..{array.max()}.')
    return array.astype(np.uint8)
