"""Converter pieces on hand-made inputs: poses, splits, flags, versions."""
import numpy as np
import pytest

from projects.occ_common.datasets.converters.nuscenes_occ_converter import (
    pose_matrix, split_scenes)
from projects.occ_common.datasets.info_format import (INFO_VERSION,
                                                      check_info_file,
                                                      weather_flags)


def test_pose_matrix_by_hand():
    """A 90 deg yaw quaternion (cos 45, 0, 0, sin 45) and translation
    (1, 2, 3) map (1, 0, 0) to (0, 1, 0) + (1, 2, 3) = (1, 3, 3)."""
    half = np.sqrt(0.5)
    mat = pose_matrix(dict(rotation=[half, 0, 0, half],
                           translation=[1, 2, 3]))
    np.testing.assert_allclose(mat @ [1, 0, 0, 1], [1, 3, 3, 1], atol=1e-12)


def test_real_splits():
    """v1.0-mini uses nuScenes' mini_train / mini_val (scene-0103 and
    scene-0916 are val); v1.0-trainval its train / val (scene-0001 train,
    scene-0003 val); scenes absent from the database are dropped."""
    mini = split_scenes(['scene-0061', 'scene-0103', 'scene-0916'],
                        'v1.0-mini')
    assert mini == dict(train=['scene-0061'],
                        val=['scene-0103', 'scene-0916'])
    full = split_scenes(['scene-0001', 'scene-0003'], 'v1.0-trainval')
    assert full == dict(train=['scene-0001'], val=['scene-0003'])
    assert split_scenes([], 'v1.0-test') == dict(test=[])


def test_synthetic_and_explicit_splits():
    """Synthetic: the last max(1, n // 5) scenes are val: 2 scenes -> 1,
    10 -> 2; one scene is both train and val (with a warning); explicit
    val scenes override, unknown ones raise naming them."""
    two = split_scenes(['scene-0002', 'scene-0001'], 'v1.0-mini',
                       synthetic=True)
    assert two == dict(train=['scene-0001'], val=['scene-0002'])
    ten = split_scenes([f's{i:02d}' for i in range(10)], 'v1.0-mini',
                       synthetic=True)
    assert ten['val'] == ['s08', 's09'] and len(ten['train']) == 8
    with pytest.warns(UserWarning, match='one scene'):
        assert split_scenes(['a'], 'v1.0-mini', synthetic=True) == dict(
            train=['a'], val=['a'])
    assert split_scenes(['a', 'b', 'c'], 'v1.0-mini', ['a']) == dict(
        train=['b', 'c'], val=['a'])
    with pytest.raises(ValueError, match=r"\['zz'\]"):
        split_scenes(['a'], 'v1.0-mini', ['zz'])


def test_weather_flags():
    """nuScenes descriptions: 'Night, rain, ...' sets both flags; 'Rain'
    capitalised counts; 'Parked cars' sets none."""
    assert weather_flags('Night, rain, parking lot') == dict(
        is_rainy=True, is_night=True)
    assert weather_flags('Rain, peds') == dict(is_rainy=True, is_night=False)
    assert weather_flags('Parked cars') == dict(is_rainy=False,
                                                is_night=False)


def test_check_info_file():
    """A current info file passes; another version, a list and a sample
    without its keys fail naming the file."""
    good = dict(metainfo=dict(info_version=INFO_VERSION), data_list=[])
    check_info_file(good, 'a.pkl')
    with pytest.raises(ValueError, match="a.pkl: info_version 'x'"):
        check_info_file(dict(good, metainfo=dict(info_version='x')), 'a.pkl')
    with pytest.raises(ValueError, match='b.pkl: expected an info file'):
        check_info_file([], 'b.pkl')
    with pytest.raises(ValueError, match=r"c.pkl: sample t lacks the keys"):
        check_info_file(dict(good, data_list=[dict(token='t')]), 'c.pkl')


def test_weather_flags_match_word_starts_only():
    """'Night, rain, parking lot' is both; 'terrain', 'train' and
    'overnight' are neither; 'raining' and 'nighttime' count."""
    from projects.occ_common.datasets.info_format import weather_flags
    assert weather_flags('Night, rain, parking lot') == dict(
        is_rainy=True, is_night=True)
    assert weather_flags('Bus passes train station over terrain') == dict(
        is_rainy=False, is_night=False)
    assert weather_flags('Parked overnight') == dict(
        is_rainy=False, is_night=False)
    assert weather_flags('Raining at nighttime') == dict(
        is_rainy=True, is_night=True)
