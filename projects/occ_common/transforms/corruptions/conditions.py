"""The corruption conditions: what each does, at which severity, and where
its scale comes from.

:data:`CONDITIONS` maps a name to a :class:`Condition`; the level of
severity ``s`` (1-5) is ``levels[s - 1]``. docs/robustness.md prints this
table. Sources:

* ``imagecorruptions``: Michaelis et al., "Benchmarking Robustness in
  Object Detection" (2019), the ImageNet-C corruptions at any image size;
  the package's five levels.
* RoboBEV: Xie et al., "RoboBEV" (2023), nuScenes-C; its easy / mid / hard
  levels are three of its five.
* MultiCorrupt: Beemelmanns et al. (IV 2024), three levels.
* Dong et al.: "Benchmarking Robustness of 3D Object Detection to Common
  Corruptions in Autonomous Driving" (CVPR 2023), five levels.
"""
from typing import Callable, NamedTuple, Optional, Sequence

from . import camera, cross_sensor, lidar, pixels

#: The severities of every condition.
MAX_SEVERITY = 5


class Condition(NamedTuple):
    """One corruption condition.

    Attributes:
        family (str): ``'camera'``, ``'lidar'`` or ``'cross-sensor'``.
        apply (Callable): ``apply(results, level, rng)``, in place.
        levels (tuple): The level of each severity 1..MAX_SEVERITY.
        scale (str): What a level is, for the docs.
        source (str): Where the scale comes from, for the docs.
        needs (str, optional): What the pipeline must provide beyond the
            loaded sample: ``'ring'`` (each point's beam index) or
            ``'previous_frame'`` (``prev_frames``). Defaults to None.
    """

    family: str
    apply: Callable
    levels: Sequence
    scale: str
    source: str
    needs: Optional[str] = None


_IC = 'imagecorruptions'


def levels_text(condition: Condition) -> str:
    """The levels of severities 1..5 as the docs print them, e.g.
    ``'0.08, 0.12, 0.18, 0.26, 0.38'`` or ``'(3, 0.1), (4, 0.5), ...'``."""

    def one(level) -> str:
        if isinstance(level, (tuple, list)):
            return '(' + ', '.join(one(v) for v in level) + ')'
        return f'{level:.3g}' if isinstance(level, float) else str(level)

    return ', '.join(one(level) for level in condition.levels)


def _pixels(name: str, levels, scale: str, source: str = _IC) -> Condition:
    return Condition('camera', camera.every_view(getattr(pixels, name)),
                     tuple(levels), scale, source)


CONDITIONS = dict(
    # -- every view's pixels: noise, blur, weather, digital -----------------
    gaussian_noise=_pixels('gaussian_noise', [.08, .12, .18, .26, .38],
                           'noise sigma (x 255)'),
    shot_noise=_pixels('shot_noise', [60, 25, 12, 5, 3],
                       'photons at full brightness'),
    impulse_noise=_pixels('impulse_noise', [.03, .06, .09, .17, .27],
                          'share of values set to 0 / 255'),
    defocus_blur=_pixels('defocus_blur', [(3, .1), (4, .5), (6, .5), (8, .5),
                                          (10, .5)],
                         'disk radius, anti-alias sigma (px)'),
    motion_blur=_pixels('motion_blur', [(10, 3), (15, 5), (15, 8), (15, 12),
                                        (20, 15)],
                        'streak radius, sigma (px)'),
    fog=_pixels('fog', [(1.5, 2), (2., 2), (2.5, 1.7), (2.5, 1.5), (3., 1.4)],
                'fractal strength, decay'),
    snow=_pixels('snow', [(.1, .3, 3, .5, 10, 4, .8), (.2, .3, 2, .5, 12, 4,
                                                       .7),
                          (.55, .3, 4, .9, 12, 8, .7),
                          (.55, .3, 4.5, .85, 12, 8, .65),
                          (.55, .3, 2.5, .85, 12, 12, .55)],
                 'flake mean, std, zoom, threshold, streak radius, sigma, '
                 'blend'),
    brightness=_pixels('brightness', [.1, .2, .3, .4, .5],
                       'added to HSV value'),
    low_light=_pixels('low_light', [(.6, 600, .008), (.5, 250, .012),
                                    (.4, 120, .018), (.3, 50, .026),
                                    (.2, 30, .038)],
                      'top of the range, photons, read noise sigma',
                      'RoboBEV (its levels indexed from 0 there)'),
    contrast=_pixels('contrast', [.4, .3, .2, .1, .05],
                     'factor towards the mean'),
    pixelate=_pixels('pixelate', [.6, .5, .4, .3, .25],
                     'scale of the coarse image'),
    jpeg_compression=_pixels('jpeg_compression', [25, 18, 15, 10, 7],
                             'JPEG quality'),
    color_quant=_pixels('color_quant', [5, 4, 3, 2, 1], 'bits per channel',
                        'RoboBEV (its 4 / 3 / 2 bits are severities 2-4)'),
    # -- camera failures ----------------------------------------------------
    camera_crash=Condition('camera', camera.camera_crash, (1, 2, 3, 4, 5),
                           'black views (of 6), calibration kept',
                           'RoboBEV (easy / mid / hard: 2 / 4 / 5)'),
    camera_blackout=Condition('camera', camera.camera_blackout,
                              (.2, .4, .6, .8, 1.),
                              'probability that all views are black',
                              'ours: the whole camera system down'),
    frame_lost=Condition('camera', camera.frame_lost,
                         (1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6),
                         'probability that a view repeats its previous key '
                         'frame', 'RoboBEV (its lost frames are black)',
                         needs='previous_frame'),
    missing_views=Condition('camera', camera.missing_views, (1, 2, 3, 4, 5),
                            'views dropped with their calibration',
                            'MultiCorrupt (missing camera)'),
    # -- LiDAR --------------------------------------------------------------
    beam_reduction=Condition('lidar', lidar.beam_reduction, (2, 3, 4, 6, 8),
                             'every n-th ring kept (16, 11, 8, 6, 4 of 32 '
                             'beams)', 'MultiCorrupt (16 / 8 / 4 beams)',
                             needs='ring'),
    point_reduction=Condition('lidar', lidar.point_reduction,
                              (.7, .75, .8, .85, .9),
                              'share of points dropped',
                              'MultiCorrupt (70 / 80 / 90 %)'),
    lidar_fog=Condition('lidar', lidar.lidar_fog,
                        (.005, .01, .02, .03, .06),
                        'extinction alpha (1/m): kept with exp(-2 alpha r)',
                        'Dong et al. (alpha of Hahner et al.\'s fog)'),
    lidar_crosstalk=Condition('lidar', lidar.lidar_crosstalk,
                              (.004, .008, .012, .016, .02),
                              'share of points moved by N(0, 3 m)',
                              'Dong et al.'),
    lidar_missing=Condition('lidar', lidar.lidar_missing,
                            (.2, .4, .6, .8, 1.),
                            'probability that the sample has no points',
                            'ours: the LiDAR down'),
    # -- between the sensors -----------------------------------------------
    spatial_misalignment=Condition(
        'cross-sensor', cross_sensor.spatial_misalignment,
        ((.3, .07), (.6, .14), (1., .21), (1.3, .28), (1.6, .35)),
        'rotation (deg), shift (m) of each camera\'s extrinsics',
        'Dong et al. (the expected size of their additive noise)'),
    temporal_misalignment=Condition(
        'cross-sensor', cross_sensor.temporal_misalignment,
        (2, 4, 6, 8, 10), 'LiDAR late by n sweeps (50 ms each)',
        'Dong et al.'),
)
