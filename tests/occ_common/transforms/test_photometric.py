"""MultiViewPhotoMetric: each step changes the pixels as it claims, each
view draws its own parameters, and nothing leaves 0-255 or its dtype."""
import numpy as np
import pytest

from projects.occ_common.transforms.photometric import (IDENTITY,
                                                        MultiViewPhotoMetric,
                                                        distort_view)


def _view(bgr, shape=(2, 3)):
    return np.tile(np.array(bgr, np.uint8), shape + (1, ))


def test_identity_leaves_the_view():
    img = np.random.default_rng(0).integers(0, 256, (4, 5, 3), np.uint8)
    np.testing.assert_array_equal(distort_view(img, IDENTITY), img)


@pytest.mark.parametrize(
    'change, bgr, expected',
    [
        # Brightness adds: 100 + 20 = 120; 250 + 20 clips at 255.
        (dict(brightness=20.0), (100, 100, 250), (120, 120, 255)),
        # Contrast multiplies: 100 x 1.5 = 150, 40 x 1.5 = 60.
        (dict(contrast=1.5), (100, 40, 100), (150, 60, 150)),
        # Brightness then contrast: (100 - 10) x 0.5 = 45.
        (dict(brightness=-10.0, contrast=0.5), (100, 100, 100),
         (45, 45, 45)),
        # Saturation 0 leaves V = the largest channel in all three.
        (dict(saturation=0.0), (50, 100, 200), (200, 200, 200)),
        # Saturation 0.5 halves S = (200 - 50) / 200: the smallest channel
        # rises to V (1 - S / 2) = 125, and the middle one keeps its hue's
        # place between them, 125 + (100 - 50) / 2 = 150.
        (dict(saturation=0.5), (50, 100, 200), (125, 150, 200)),
        # Hue +120 degrees: red (BGR 0, 0, 255) turns green.
        (dict(hue=120.0), (0, 0, 255), (0, 255, 0)),
        # Hue -120 degrees: red turns blue.
        (dict(hue=-120.0), (0, 0, 255), (255, 0, 0)),
    ])
def test_each_step_changes_the_pixels(change, bgr, expected):
    out = distort_view(_view(bgr), dict(IDENTITY, **change))
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, _view(expected))


def test_contrast_commutes_with_the_colour_steps():
    """Contrast scales V and keeps H and S, so scaling the contrast of a
    view whose saturation is changed too equals scaling the result: BGR
    (50, 100, 200) with saturation 0.5 is (125, 150, 200) (above), and
    with contrast 0.8 as well 0.8 x that, (100, 120, 160)."""
    out = distort_view(
        _view((50, 100, 200)), dict(IDENTITY, contrast=0.8, saturation=0.5))
    np.testing.assert_array_equal(out, _view((100, 120, 160)))


def _sample(num_views=6, **kwargs):
    rng = np.random.default_rng(1)
    imgs = [
        rng.integers(0, 256, (4, 5, 3), np.uint8) for _ in range(num_views)
    ]
    out = MultiViewPhotoMetric(**kwargs)(dict(img=[i.copy() for i in imgs]))
    return imgs, out


def test_each_view_draws_its_own_params():
    """With prob 1 every step happens, so every view has its own draw of
    each parameter within its range, and its recorded parameters reproduce
    its output."""
    np.random.seed(0)
    imgs, out = _sample(prob=1.0)
    params = out['img_photometric_params']
    assert len(params) == 6
    for key, (low, high) in (('brightness', (-32, 32)),
                             ('contrast', (0.5, 1.5)),
                             ('saturation', (0.5, 1.5)), ('hue', (-18, 18))):
        values = [p[key] for p in params]
        assert len(set(values)) == 6, key
        assert all(low <= v <= high for v in values), key
    for img, distorted, p in zip(imgs, out['img'], params):
        assert distorted.dtype == np.uint8 and distorted.shape == img.shape
        np.testing.assert_array_equal(distorted, distort_view(img, p))


def test_prob_zero_changes_nothing():
    np.random.seed(0)
    imgs, out = _sample(prob=0.0)
    assert out['img_photometric_params'] == [IDENTITY] * 6
    for img, distorted in zip(imgs, out['img']):
        np.testing.assert_array_equal(distorted, img)


def test_prob_is_the_share_of_views_a_step_touches():
    """600 views at prob 0.5: brightness moves in 0.5 of them (binomial
    standard deviation 0.02, so within 0.4-0.6)."""
    np.random.seed(0)
    _, out = _sample(num_views=600, prob=0.5)
    moved = np.mean([p['brightness'] != 0 for p in
                     out['img_photometric_params']])
    assert 0.4 < moved < 0.6


def test_float_views_stay_float():
    view = np.full((2, 2, 3), 100.0, np.float32)
    out = distort_view(view, dict(IDENTITY, brightness=0.5))
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, 100.5)


@pytest.mark.parametrize('kwargs', [
    dict(contrast_range=(1.5, 0.5)),
    dict(saturation_range=(-0.1, 1.0)),
    dict(brightness_delta=-1),
    dict(hue_delta=200),
    dict(prob=1.5),
])
def test_bad_ranges_are_refused(kwargs):
    with pytest.raises(ValueError, match='MultiViewPhotoMetric'):
        MultiViewPhotoMetric(**kwargs)


def test_a_grey_view_is_refused():
    with pytest.raises(ValueError, match='3-channel'):
        distort_view(np.zeros((2, 2, 1), np.uint8), IDENTITY)
