"""The pixel corruptions on small hand-made views, values by hand."""
import cv2
import numpy as np
import pytest

from projects.occ_common.transforms.corruptions import pixels


def rng(seed=0):
    return np.random.default_rng(seed)


def flat(value, shape=(8, 10, 3)):
    return np.full(shape, value, np.uint8)


def test_color_quant_clears_the_low_bits():
    """1 bit keeps 0 or 128: 127 -> 0, 200 -> 128; 3 bits: 200 = 0b11001000
    -> 0b11000000 = 192."""
    img = np.array([[[127, 200, 255]]], np.uint8)
    np.testing.assert_array_equal(pixels.color_quant(img, 1, rng()),
                                  [[[0, 128, 128]]])
    np.testing.assert_array_equal(pixels.color_quant(img, 3, rng()),
                                  [[[96, 192, 224]]])


def test_contrast_pulls_towards_the_channel_mean():
    """Values 0 and 200 (mean 100) at factor 0.5 become 50 and 150."""
    img = np.zeros((2, 2, 3), np.uint8)
    img[0] = 200
    out = pixels.contrast(img, 0.5, rng())
    np.testing.assert_array_equal(out[0], 150)
    np.testing.assert_array_equal(out[1], 50)


def test_brightness_adds_to_the_value_channel():
    """Grey 100 (V = 0.392) + 0.2 -> V = 0.592 -> 151 on every channel
    (grey has no saturation)."""
    out = pixels.brightness(flat(100), 0.2, rng())
    np.testing.assert_array_equal(out, 151)


def test_gaussian_noise_has_its_sigma():
    """Mid-grey keeps its mean; the noise's std is sigma * 255 = 20.4 for
    sigma 0.08 (no clipping at 128 +- 4 sigma)."""
    out = pixels.gaussian_noise(flat(128, (200, 200, 3)), 0.08, rng())
    assert out.astype(float).mean() == pytest.approx(128, abs=0.3)
    assert out.astype(float).std() == pytest.approx(20.4, rel=0.02)


def test_impulse_noise_hits_its_share():
    """27 % of the values become 0 or 255, half each."""
    out = pixels.impulse_noise(flat(128, (200, 200, 3)), 0.27, rng())
    assert (out != 128).mean() == pytest.approx(0.27, abs=0.01)
    assert (out == 255).mean() == pytest.approx(0.135, abs=0.01)


def test_shot_noise_is_poisson():
    """At 12 photons a value of 255 * 0.5 counts Poisson(6) photons: mean
    0.5, std sqrt(6) / 12 = 0.204 of full scale."""
    out = pixels.shot_noise(flat(128, (200, 200, 3)), 12, rng()) / 255.0
    assert out.mean() == pytest.approx(128 / 255, abs=0.01)
    assert out.std() == pytest.approx(np.sqrt(6 * 128 / 127.5) / 12,
                                      rel=0.03)


def test_blur_kernels_keep_the_brightness():
    """Both kernels sum to 1 (a flat view stays flat); the motion streak
    runs from the centre along its angle: at 0 degrees to the right."""
    kernel = pixels.motion_kernel(radius=3, sigma=2, angle_deg=0)
    assert kernel.sum() == pytest.approx(1)
    centre = kernel.shape[0] // 2
    row = kernel[centre]
    assert (row[centre:centre + 7] > 0).all() and row[:centre].sum() == 0
    assert kernel.sum() == pytest.approx(row.sum())
    np.testing.assert_array_equal(
        pixels.motion_blur(flat(90), (3, 2), rng()), 90)
    np.testing.assert_array_equal(
        pixels.defocus_blur(flat(90), (3, 0.1), rng()), 90)


def test_defocus_blur_spreads_a_dot_over_a_disk():
    """A bright dot becomes a disk of radius ~6 px: nothing beyond 8 px
    (the 3x3 anti-alias adds one pixel), its mass kept."""
    img = np.zeros((41, 41, 3), np.uint8)
    img[20, 20] = 255
    out = pixels.defocus_blur(img, (6, 0.5), rng()).astype(float)
    yy, xx = np.mgrid[:41, :41]
    far = np.hypot(yy - 20, xx - 20) > 8
    assert out[far].sum() == 0
    assert out[..., 0].sum() == pytest.approx(255, rel=0.2)


def test_plasma_fractal_is_periodic_and_normalised():
    fractal = pixels.plasma_fractal(64, 2.0, rng())
    assert fractal.shape == (64, 64)
    assert fractal.min() == 0 and fractal.max() == pytest.approx(1)
    with pytest.raises(ValueError, match='power of two'):
        pixels.plasma_fractal(48, 2.0, rng())


def test_pixelate_makes_blocks():
    """At 0.5 a 16-wide view keeps 8 distinct columns, in pairs."""
    img = np.tile(np.arange(16, dtype=np.uint8)[None, :, None] * 10,
                  (4, 1, 3))
    out = pixels.pixelate(img, 0.5, rng())
    np.testing.assert_array_equal(out[:, 0::2], out[:, 1::2])
    assert len(np.unique(out[0, :, 0])) == 8


def test_jpeg_compression_round_trips_through_opencv():
    img = np.random.default_rng(1).integers(0, 255, (32, 32, 3), np.uint8)
    out = pixels.jpeg_compression(img, 7, rng())
    assert out.shape == img.shape and out.dtype == np.uint8
    ok, buffer = cv2.imencode('.jpg', img, [cv2.IMWRITE_JPEG_QUALITY, 7])
    np.testing.assert_array_equal(out, cv2.imdecode(buffer, 1))


def test_low_light_darkens():
    """White stretched to the level's top (0.2) stays near 0.2 * 255 = 51
    plus noise; black stays near black."""
    img = np.zeros((100, 100, 3), np.uint8)
    img[:50] = 255
    out = pixels.low_light(img, (0.2, 30, 0.038), rng()).astype(float)
    assert out[:50].mean() == pytest.approx(51, abs=3)
    assert out[50:].mean() < 10
