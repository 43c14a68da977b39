"""Class colours by name, conventions and palette validation."""
import numpy as np
import pytest

from projects.occ_common.datasets.nuscenes_classes import (OCC3D_CLASS_NAMES,
                                                           OCC_CLASS_PALETTE)
from projects.occ_common.visualization import (class_palette,
                                               convention_classes,
                                               resolve_palette)
from projects.occ_common.visualization.palette import FALLBACK_COLOURS


def test_nuscenes_names_take_the_challenge_colours():
    """Occ3D's 18 names give back OCC_CLASS_PALETTE row for row."""
    np.testing.assert_array_equal(
        class_palette(OCC3D_CLASS_NAMES), OCC_CLASS_PALETTE)


def test_surroundocc_and_occ3d_colour_a_class_alike():
    """'car' is label 4 in both conventions and (255, 158, 0) in both."""
    for convention in ('surroundocc', 'occ3d'):
        names, _ = convention_classes(convention)
        assert tuple(class_palette(names)[4]) == (255, 158, 0)
    assert convention_classes('surroundocc')[1] == 0
    assert convention_classes('occ3d')[1] == 17


def test_unknown_names_take_the_fallback_of_their_label():
    """'empty' (label 0) -> fallback 0; 'road' (label 2) -> fallback 2."""
    palette = class_palette(('empty', 'car', 'road'))
    np.testing.assert_array_equal(palette[0], FALLBACK_COLOURS[0])
    np.testing.assert_array_equal(palette[2], FALLBACK_COLOURS[2])
    assert tuple(palette[1]) == (255, 158, 0)


def test_resolve_palette_validates_user_colours():
    """A (C, 3) palette passes as uint8; other shapes / values raise."""
    names = ('empty', 'car')
    out = resolve_palette(names, [[0, 0, 0], [10, 20, 30]])
    assert out.dtype == np.uint8 and out[1].tolist() == [10, 20, 30]
    with pytest.raises(ValueError, match=r'shape \(2, 3\)'):
        resolve_palette(names, [[0, 0, 0]])
    with pytest.raises(ValueError, match='0..255'):
        resolve_palette(names, [[0, 0, 0], [0, 0, 300]])
    with pytest.raises(ValueError, match='at least one'):
        class_palette(())
    with pytest.raises(ValueError, match="'kitti'"):
        convention_classes('kitti')
