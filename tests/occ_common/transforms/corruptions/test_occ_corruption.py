"""OccCorruption on a sample of the tiny world as the loaders leave it:
every condition is deterministic and its effect on the input grows with
severity."""
import copy

import numpy as np
import pytest

from projects.occ_common.testing.corruption_samples import loaded_sample
from projects.occ_common.transforms.corruptions import (CONDITIONS,
                                                        MAX_SEVERITY,
                                                        OccCorruption)
from projects.occ_common.transforms.corruptions.cross_sensor import \
    rotation_about
from projects.occ_common.transforms.corruptions.lidar import points_array

SEVERITIES = range(1, MAX_SEVERITY + 1)
#: Conditions whose effect is a probability per sample: measured as a
#: share over many samples (tokens) instead of on one.
PER_SAMPLE_PROBABILITY = ('camera_blackout', 'lidar_missing')


@pytest.fixture(scope='module')
def sample(converted_tiny_world):
    """The tiny world's second key frame (its previous one is the first)
    after the loaders."""
    return loaded_sample(converted_tiny_world, index=1)


def corrupt(sample, condition, severity, seed=0, token=None):
    results = copy.deepcopy(sample)
    if token is not None:
        results['token'] = token
    return OccCorruption(condition, severity, seed)(results)


def _state(results):
    """Everything a condition may change, as arrays."""
    out = {f'img{i}': img for i, img in enumerate(results['img'])}
    out['points'] = points_array(results).copy()
    for key in ('lidar2cam', 'lidar2img', 'cam2ego', 'cam2img'):
        out[key] = np.asarray(results[key])
    out['cam_names'] = np.asarray(results['cam_names'])
    return out


def test_conditions_table():
    """Every condition has MAX_SEVERITY levels, a family, a scale and a
    source, and the transform lists them all."""
    assert OccCorruption.CONDITIONS == tuple(CONDITIONS)
    assert OccCorruption.MAX_SEVERITY == MAX_SEVERITY == 5
    assert len(CONDITIONS) == 24
    for name, condition in CONDITIONS.items():
        assert len(condition.levels) == MAX_SEVERITY, name
        assert condition.family in ('camera', 'lidar', 'cross-sensor')
        assert condition.scale and condition.source, name


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match='unknown condition'):
        OccCorruption('rain', 1)
    for severity in (0, 6, 2.0, True):
        with pytest.raises(ValueError, match='severity must be an integer'):
            OccCorruption('fog', severity)


@pytest.mark.parametrize('condition', list(CONDITIONS))
def test_same_input_same_output(sample, condition):
    """(sample, condition, severity, seed) fixes the output bit for bit;
    another seed changes it where the condition draws anything at 3."""
    first = _state(corrupt(sample, condition, 3))
    again = _state(corrupt(sample, condition, 3))
    assert first.keys() == again.keys()
    for key in first:
        np.testing.assert_array_equal(first[key], again[key], err_msg=key)
    deterministic = ('brightness', 'contrast', 'pixelate',
                     'jpeg_compression', 'color_quant', 'beam_reduction',
                     'temporal_misalignment', 'defocus_blur')
    # At probability 0.6 a seed may or may not hit: not compared.
    if condition in deterministic + PER_SAMPLE_PROBABILITY + (
            'frame_lost', ):
        return
    other = _state(corrupt(sample, condition, 3, seed=1))
    assert any(
        first[k].shape != other[k].shape or not np.array_equal(
            first[k], other[k]) for k in first)


def _image_change(clean, results):
    return np.mean([
        np.abs(a.astype(float) - b).mean()
        for a, b in zip(clean['img'], results['img'])
    ])


def _decorrelation(clean, results):
    """1 - the correlation of each view's pixels with the clean ones."""
    return np.mean([
        1 - np.corrcoef(a.astype(float).ravel(), b.astype(float).ravel())[0,
                                                                          1]
        for a, b in zip(clean['img'], results['img'])
    ])


def _distinct_columns(results):
    """Columns of each view that differ from their left neighbour."""
    return sum(int((np.diff(img.astype(int), axis=1) != 0).any(
        axis=(0, 2)).sum()) for img in results['img'])


def _black_views(results):
    return sum(int(not img.any()) for img in results['img'])


@pytest.mark.parametrize('condition', [
    c for c, spec in CONDITIONS.items()
    if spec.family == 'camera' and c not in PER_SAMPLE_PROBABILITY
])
def test_camera_effect_grows_with_severity(sample, condition):
    """Measured on the views: the mean absolute pixel change for the pixel
    corruptions (pixelate: the fewer distinct columns, its coarser
    blocks; fog: the scene's decorrelation), the black views of a crash
    (exactly 1..5), the views missing (exactly 1..5, their calibration
    gone) and the views showing the previous frame (a growing set)."""
    runs = [corrupt(sample, condition, s) for s in SEVERITIES]
    if condition == 'camera_crash':
        assert [_black_views(r) for r in runs] == [1, 2, 3, 4, 5]
        assert all(len(r['lidar2img']) == 6 for r in runs)
        return
    if condition == 'missing_views':
        assert [len(r['img']) for r in runs] == [5, 4, 3, 2, 1]
        for r in runs:
            assert len(r['lidar2img']) == len(r['cam_names']) == \
                r['num_views'] == len(r['img'])
            kept = [sample['cam_names'].index(c) for c in r['cam_names']]
            np.testing.assert_array_equal(
                r['lidar2img'], np.asarray(sample['lidar2img'])[kept])
        return
    if condition == 'frame_lost':
        stale = [{i for i, (a, b) in enumerate(zip(sample['img'], r['img']))
                  if not np.array_equal(a, b)} for r in runs]
        assert all(a <= b for a, b in zip(stale, stale[1:]))
        assert len(stale[-1]) > len(stale[0])
        return
    if condition == 'pixelate':
        columns = [_distinct_columns(r) for r in runs]
        assert columns == sorted(columns, reverse=True)
        assert columns[-1] < columns[0] < _distinct_columns(sample)
        return
    if condition == 'fog':
        # Levels 3 and 4 of imagecorruptions share the fog's strength and
        # differ in its roughness, which may hide a little more or less of
        # one sample: the scene's decorrelation grows over four seeds.
        change = [
            np.mean([_decorrelation(sample, corrupt(sample, 'fog', s, seed))
                     for seed in range(4)]) for s in SEVERITIES
        ]
    else:
        change = [_image_change(sample, r) for r in runs]
    assert change == sorted(change) and change[0] > 0, change


def test_frame_lost_shows_the_previous_frame(sample, converted_tiny_world):
    """A lost view holds exactly the previous key frame's image of that
    camera; the rest stay."""
    previous = loaded_sample(converted_tiny_world, index=0)
    results = corrupt(sample, 'frame_lost', 5)
    shown = 0
    for now, before, out in zip(sample['img'], previous['img'],
                                results['img']):
        assert np.array_equal(out, now) or np.array_equal(out, before)
        shown += not np.array_equal(out, now)
    assert shown > 0


@pytest.mark.parametrize('condition', PER_SAMPLE_PROBABILITY)
def test_per_sample_probability_grows_with_severity(sample, condition):
    """Over 60 tokens the share of samples without cameras (all views
    black) / without points is 0.2, 0.4, ... 1.0 within three binomial
    standard deviations, never lower at a higher severity, and exactly
    all at 5."""
    hit = np.zeros((MAX_SEVERITY, 60), bool)
    for s in SEVERITIES:
        for t in range(60):
            # Neither condition changes the sample in place: no deep copy.
            out = OccCorruption(condition, s)(dict(
                token=f'token-{t}', img=list(sample['img']),
                points=sample['points']))
            hit[s - 1, t] = (_black_views(out) == 6 if condition ==
                             'camera_blackout' else
                             len(points_array(out)) == 0)
    assert (hit[1:] >= hit[:-1]).all()  # common random numbers
    assert hit[-1].all()
    for s, row in zip(SEVERITIES, hit):
        p = 0.2 * s
        assert abs(row.mean() - p) <= 3 * np.sqrt(p * (1 - p) / 60) + 1e-9


@pytest.mark.parametrize('condition', [
    c for c, spec in CONDITIONS.items()
    if spec.family == 'lidar' and c not in PER_SAMPLE_PROBABILITY
])
def test_lidar_effect_grows_with_severity(sample, condition):
    """Points kept fall with severity (beam and point reduction, fog);
    crosstalk moves round(share * P) of them, 0.4 % to 2 %."""
    total = len(points_array(sample))
    runs = [corrupt(sample, condition, s) for s in SEVERITIES]
    if condition == 'lidar_crosstalk':
        clean = points_array(sample)
        moved = [int((points_array(r)[:, :3] != clean[:, :3]).any(1).sum())
                 for r in runs]
        assert moved == [round(share * total) for share in
                         (.004, .008, .012, .016, .02)]
        return
    kept = [len(points_array(r)) for r in runs]
    assert kept == sorted(kept, reverse=True) and kept[-1] < kept[0] < total
    if condition == 'point_reduction':
        assert kept == [total - round(share * total)
                        for share in (.7, .75, .8, .85, .9)]


def _angle_deg(rotation):
    return np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1)))


def test_spatial_misalignment_offset_is_exact(sample):
    """Every camera's told extrinsics differ from the true ones by a
    rotation of exactly 0.3 .. 1.6 degrees and a shift of exactly 0.07 ..
    0.35 m; lidar2img follows; lidar2ego = cam2ego @ lidar2cam still holds
    (one consistent wrong camera pose); images and points are untouched."""
    true_l2c = np.asarray(sample['lidar2cam'])
    true_l2e = np.asarray(sample['cam2ego']) @ true_l2c
    for s, (angle, shift) in zip(SEVERITIES,
                                 CONDITIONS['spatial_misalignment'].levels):
        out = corrupt(sample, 'spatial_misalignment', s)
        offsets = out['lidar2cam'] @ np.linalg.inv(true_l2c)
        for offset in offsets:
            assert _angle_deg(offset[:3, :3]) == pytest.approx(angle, 1e-6)
            assert np.linalg.norm(offset[:3, 3]) == pytest.approx(shift)
        np.testing.assert_allclose(
            out['lidar2img'],
            out['img_aug_matrix'] @ out['cam2img'] @ out['lidar2cam'])
        np.testing.assert_allclose(out['cam2ego'] @ out['lidar2cam'],
                                   true_l2e, atol=1e-9)
        np.testing.assert_array_equal(points_array(out),
                                      points_array(sample))
        assert all(np.array_equal(a, b)
                   for a, b in zip(out['img'], sample['img']))


def test_temporal_misalignment_delay_grows(sample):
    """The tiny world's sweeps are 50 ms apart: the LiDAR is 0.1, 0.2, 0.3,
    0.4, 0.5 s late, and its points move further from where they are (the
    ego drives on)."""
    runs = [corrupt(sample, 'temporal_misalignment', s) for s in SEVERITIES]
    delays = [r['corruption_delay_s'] for r in runs]
    np.testing.assert_allclose(delays, [.1, .2, .3, .4, .5], atol=1e-6)
    shift = [np.linalg.norm(points_array(r)[:, :3] -
                            points_array(sample)[:, :3], axis=1).mean()
             for r in runs]
    assert shift == sorted(shift) and shift[0] > 0


def test_rotation_about_is_rodrigues():
    """A quarter turn about z maps x to y."""
    np.testing.assert_allclose(
        rotation_about(np.array([0., 0., 1.]), np.pi / 2) @ [1, 0, 0],
        [0, 1, 0], atol=1e-12)


def test_record_and_repr(sample):
    """The state records what was applied; the ring indices are gone."""
    out = corrupt(sample, 'beam_reduction', 2)
    assert out['corruption'] == dict(condition='beam_reduction',
                                     severity=2, seed=0)
    assert 'points_ring' not in out
    assert repr(OccCorruption('fog', 4, 7)) == \
        "OccCorruption(condition='fog', severity=4, seed=7)"


def test_beam_reduction_keeps_every_nth_ring(sample):
    """At severity 3 (step 4) exactly the points of rings 0, 4, ..., 28
    stay, key frame and sweeps."""
    ring = sample['points_ring']
    out = corrupt(sample, 'beam_reduction', 3)
    np.testing.assert_array_equal(points_array(out),
                                  points_array(sample)[ring % 4 == 0])
    assert set(np.unique(ring[ring % 4 == 0])) <= set(range(0, 32, 4))


def test_beam_reduction_needs_the_rings(sample):
    results = copy.deepcopy(sample)
    del results['points_ring']
    with pytest.raises(ValueError, match='record_ring=True'):
        OccCorruption('beam_reduction', 1)(results)


def test_frame_lost_needs_the_previous_frame(sample):
    results = copy.deepcopy(sample)
    del results['prev_frames']
    with pytest.raises(ValueError, match='num_frames=2'):
        OccCorruption('frame_lost', 5)(results)
