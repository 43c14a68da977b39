"""The common image corruptions of one camera view, in numpy and OpenCV.

The corruptions of Hendrycks & Dietterich's ImageNet-C as the
``imagecorruptions`` package (Michaelis et al., 2019) defines them for
images of any size, at its five severity levels, plus the two that
RoboBEV's nuScenes-C adds (low light, colour quantisation). Written here
rather than taken from ``imagecorruptions`` 1.1.2 because that package
installs ``opencv-python`` (the GUI build, which needs libGL and
overwrites the ``cv2`` of the ``opencv-python-headless`` this stack uses)
and scikit-image, and draws from numpy's global random state, which a
seeded, per-sample corruption cannot use. Every function takes a
generator and is deterministic given it; the constants (which
:mod:`.conditions` lists per severity) are the packages' own.

Each function maps a view, uint8 BGR (the loader's ``color_type='color'``)
Shape (H, W, 3), to a view of the same shape and dtype.
"""
from typing import Sequence, Tuple

import cv2
import numpy as np


def _unit(img: np.ndarray) -> np.ndarray:
    """uint8 0-255 -> float32 0-1."""
    return img.astype(np.float32) / np.float32(255.0)


def _uint8(x: np.ndarray) -> np.ndarray:
    """float 0-1 -> uint8 0-255, clipped and rounded."""
    return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


# ----------------------------------------------------------------------
# Noise
# ----------------------------------------------------------------------
def gaussian_noise(img: np.ndarray, sigma: float,
                   rng: np.random.Generator) -> np.ndarray:
    """Add N(0, ``sigma``) to every value (``sigma`` in units of 255)."""
    x = _unit(img)
    return _uint8(x + rng.normal(0.0, sigma, x.shape).astype(np.float32))


def shot_noise(img: np.ndarray, photons: float,
               rng: np.random.Generator) -> np.ndarray:
    """Photon noise: Poisson counts of ``photons`` at full brightness."""
    x = _unit(img).astype(np.float64)
    return _uint8(rng.poisson(x * photons) / float(photons))


def impulse_noise(img: np.ndarray, amount: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Salt and pepper: a share ``amount`` of the values set to 0 or 255,
    each value on its own (as scikit-image's ``random_noise`` does)."""
    out = img.copy()
    hit = rng.random(img.shape) < amount
    salt = rng.random(img.shape) < 0.5
    out[hit & salt] = 255
    out[hit & ~salt] = 0
    return out


def low_light(img: np.ndarray, level: Tuple[float, float, float],
              rng: np.random.Generator) -> np.ndarray:
    """RoboBEV's low light: the range stretched to ``[0, c]`` with gamma
    2, then the sensor's Poisson-Gaussian noise of a dim scene.

    Args:
        level (tuple): ``(c, photons, sigma)``.
    """
    top, photons, sigma = level
    x = _unit(img).astype(np.float64)
    lo, hi = x.min(), x.max()
    x = ((x - lo) / max(hi - lo, 1e-12))**2 * top
    x = np.clip(rng.poisson(x * photons) / float(photons), 0, 1)
    return _uint8(x + rng.normal(0.0, sigma, x.shape))


# ----------------------------------------------------------------------
# Blur
# ----------------------------------------------------------------------
def _disk_kernel(radius: int, alias_blur: float) -> np.ndarray:
    """A normalised disk of ``radius`` pixels, anti-aliased by a small
    Gaussian, on a square of at least 17 pixels."""
    half = max(8, int(radius))
    axis = np.arange(-half, half + 1)
    xx, yy = np.meshgrid(axis, axis)
    disk = (xx**2 + yy**2 <= radius**2).astype(np.float32)
    disk /= disk.sum()
    size = 3 if radius <= 8 else 5
    return cv2.GaussianBlur(disk, (size, size), alias_blur)


def defocus_blur(img: np.ndarray, level: Tuple[float, float],
                 rng: np.random.Generator) -> np.ndarray:
    """An out-of-focus lens: the view convolved with a disk.

    Args:
        level (tuple): ``(radius, alias_blur)`` in pixels.
    """
    kernel = _disk_kernel(*level)
    return _uint8(cv2.filter2D(_unit(img), -1, kernel))


def motion_kernel(radius: int, sigma: float, angle_deg: float) -> np.ndarray:
    """A one-sided streak: weights ``exp(-i^2 / 2 sigma^2)`` of the pixels
    ``i = 0 .. 2 radius`` steps along ``angle_deg``, normalised.

    Returns:
        np.ndarray: Correlation kernel (``cv2.filter2D``), anchored at
        its centre. Shape (4 radius + 3, 4 radius + 3).
    """
    width = 2 * int(radius) + 1
    weights = np.exp(-np.arange(width)**2 / (2.0 * sigma**2))
    weights /= weights.sum()
    kernel = np.zeros((2 * width + 1, 2 * width + 1), np.float32)
    angle = np.deg2rad(angle_deg)
    for i, weight in enumerate(weights):  # 2 radius + 1 fixed steps
        dy = int(np.round(i * np.sin(angle)))
        dx = int(np.round(i * np.cos(angle)))
        kernel[width + dy, width + dx] += weight
    return kernel


def _streak(x: np.ndarray, radius: int, sigma: float,
            angle_deg: float) -> np.ndarray:
    """``x`` (float) smeared along a streak; edges repeat outwards."""
    return cv2.filter2D(x, -1, motion_kernel(radius, sigma, angle_deg),
                        borderType=cv2.BORDER_REPLICATE)


def motion_blur(img: np.ndarray, level: Tuple[float, float],
                rng: np.random.Generator) -> np.ndarray:
    """A camera moving during the exposure, at a random angle in
    [-45, 45] degrees.

    Args:
        level (tuple): ``(radius, sigma)`` of :func:`motion_kernel`.
    """
    angle = rng.uniform(-45.0, 45.0)
    return _uint8(_streak(_unit(img), level[0], level[1], angle))


# ----------------------------------------------------------------------
# Weather
# ----------------------------------------------------------------------
def plasma_fractal(size: int, decay: float,
                   rng: np.random.Generator) -> np.ndarray:
    """A periodic diamond-square height map in [0, 1].

    Every octave sets the centre of each square (the mean of its four
    corners) and then the middle of each edge (the mean of its two corners
    and the two centres beside it), each plus ``amp * U(-amp, amp)``; the
    amplitude starts at 100 and is divided by ``decay`` per octave (a
    lower decay keeps more fine structure: denser fog).

    Args:
        size (int): Side, a power of two.
        decay (float): Amplitude ratio of one octave to the next.
        rng (np.random.Generator): The draws.

    Returns:
        np.ndarray: float32. Shape (size, size).
    """
    if size < 2 or size & (size - 1):
        raise ValueError(f'plasma_fractal: size must be a power of two >= '
                         f'2, got {size}')
    grid = np.zeros((size, size), np.float64)
    step, amp = size, 100.0
    while step >= 2:  # log2(size) octaves
        half = step // 2
        corners = grid[0::step, 0::step]
        right = np.roll(corners, -1, axis=1)
        below = np.roll(corners, -1, axis=0)
        centre = (corners + right + below + np.roll(below, -1, axis=1)) / 4
        grid[half::step, half::step] = centre + amp * rng.uniform(
            -amp, amp, centre.shape)
        centres = grid[half::step, half::step]
        top = (corners + right + centres + np.roll(centres, 1, axis=0)) / 4
        grid[0::step, half::step] = top + amp * rng.uniform(
            -amp, amp, top.shape)
        left = (corners + below + centres + np.roll(centres, 1, axis=1)) / 4
        grid[half::step, 0::step] = left + amp * rng.uniform(
            -amp, amp, left.shape)
        step, amp = half, amp / decay
    grid -= grid.min()
    return (grid / max(grid.max(), 1e-12)).astype(np.float32)


def fog(img: np.ndarray, level: Tuple[float, float],
        rng: np.random.Generator) -> np.ndarray:
    """Fog: a plasma fractal added and the range compressed.

    Args:
        level (tuple): ``(strength, decay)`` of :func:`plasma_fractal`.
    """
    strength, decay = level
    height, width = img.shape[:2]
    size = 1 << max(1, int(np.ceil(np.log2(max(height, width)))))
    x = _unit(img)
    top = x.max()
    x = x + strength * plasma_fractal(size, decay,
                                      rng)[:height, :width, None]
    return _uint8(x * top / (top + strength))


def _zoom_centre(layer: np.ndarray, factor: float) -> np.ndarray:
    """The centre ``1 / factor`` of ``layer`` resized back to its size."""
    height, width = layer.shape
    crop_h = int(np.ceil(height / factor))
    crop_w = int(np.ceil(width / factor))
    top, left = (height - crop_h) // 2, (width - crop_w) // 2
    crop = layer[top:top + crop_h, left:left + crop_w]
    return cv2.resize(crop, (width, height), interpolation=cv2.INTER_LINEAR)


def snow(img: np.ndarray, level: Sequence[float],
         rng: np.random.Generator) -> np.ndarray:
    """Falling snow: a thresholded, zoomed noise layer streaked downwards
    at a random angle in [-135, -45] degrees, added twice (as is and
    turned by 180 degrees) to a view whitened towards its grey.

    Args:
        level (Sequence[float]): ``(mean, std, zoom, threshold,
            streak radius, streak sigma, blend)``.
    """
    mean, std, zoom, threshold, radius, sigma, blend = level
    x = _unit(img)
    layer = rng.normal(mean, std, x.shape[:2]).astype(np.float32)
    layer = _zoom_centre(layer, zoom)
    layer[layer < threshold] = 0
    layer = np.clip(layer, 0, 1)
    layer = _streak(layer, int(radius), sigma, rng.uniform(-135.0, -45.0))
    layer = (np.round(layer * 255) / 255).astype(np.float32)[..., None]
    grey = cv2.cvtColor(x, cv2.COLOR_BGR2GRAY)[..., None]
    x = blend * x + (1 - blend) * np.maximum(x, grey * 1.5 + 0.5)
    return _uint8(x + layer + np.rot90(layer, 2))


def brightness(img: np.ndarray, delta: float,
               rng: np.random.Generator) -> np.ndarray:
    """Overexposure: ``delta`` added to HSV's value channel."""
    hsv = cv2.cvtColor(_unit(img), cv2.COLOR_BGR2HSV)
    hsv[..., 2] = np.clip(hsv[..., 2] + delta, 0, 1)
    return _uint8(cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR))


# ----------------------------------------------------------------------
# Digital
# ----------------------------------------------------------------------
def contrast(img: np.ndarray, factor: float,
             rng: np.random.Generator) -> np.ndarray:
    """Every channel pulled towards its mean by ``factor``."""
    x = _unit(img)
    mean = x.mean(axis=(0, 1), keepdims=True)
    return _uint8((x - mean) * factor + mean)


def pixelate(img: np.ndarray, factor: float,
             rng: np.random.Generator) -> np.ndarray:
    """Area-averaged to ``factor`` of the size, blown up by repetition."""
    height, width = img.shape[:2]
    small = cv2.resize(img, (max(1, int(width * factor)),
                             max(1, int(height * factor))),
                       interpolation=cv2.INTER_AREA)
    return cv2.resize(small, (width, height),
                      interpolation=cv2.INTER_NEAREST)


def jpeg_compression(img: np.ndarray, quality: int,
                     rng: np.random.Generator) -> np.ndarray:
    """Encoded and decoded as a JPEG of ``quality``."""
    ok, buffer = cv2.imencode('.jpg', img,
                              [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError('jpeg_compression: OpenCV could not encode the '
                         f'view of shape {img.shape}')
    return cv2.imdecode(buffer, cv2.IMREAD_COLOR)


def color_quant(img: np.ndarray, bits: int,
                rng: np.random.Generator) -> np.ndarray:
    """RoboBEV's colour quantisation: ``bits`` bits per channel (PIL's
    ``posterize``, the low bits cleared)."""
    return img & np.uint8((0xFF << (8 - int(bits))) & 0xFF)
