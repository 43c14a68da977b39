"""tools/misc/visualize_corruptions.py draws every family on the tiny
world."""
from PIL import Image

from projects.occ_common.testing.tool_logs import load_tool


def test_pictures_of_each_family(converted_tiny_world, tmp_path):
    """One condition per family at severity 5: four files, the grids two
    columns (clean, s5) of 120-pixel views wide, the cloud two plots."""
    tool = load_tool('tools/misc/visualize_corruptions.py')
    written = tool.main([
        '--info', f'{converted_tiny_world}/nuscenes_occ_infos_val.pkl',
        '--data-root', converted_tiny_world, '--out', str(tmp_path),
        '--sample', '1', '--severities', '5', '--tile-width', '120',
        '--conditions', 'fog', 'missing_views', 'lidar_fog',
        'spatial_misalignment'])
    names = sorted(p.rsplit('/', 1)[1] for p in written)
    assert names == ['camera_pixels.jpg', 'camera_views.jpg',
                     'cross_sensor.jpg', 'lidar.jpg']
    for path in written:
        width, height = Image.open(path).size
        assert width >= 240 and height > 50, path
