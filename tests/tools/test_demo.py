"""tools/demo.py: the table line that tells whether each large class was
learned."""
from projects.occ_common.testing.tool_logs import load_tool


def test_unlearned_large_classes_needs_a_gain_of_five_points():
    """Large classes (>= 1,000 GT voxels): car 0.2 -> 30.0 gained; road
    40.0 -> 44.0 gained only 4 points; bicycle (300 voxels) is not large
    whatever its IoU; free is never listed."""
    demo = load_tool('demo.py')
    counts = {'occ/gt_voxels/car': 5000, 'occ/gt_voxels/road': 90000,
              'occ/gt_voxels/bicycle': 300, 'occ/gt_voxels/free': 10**6}
    row = dict(
        metrics=dict(counts, **{'occ/car': 30.0, 'occ/road': 44.0,
                                'occ/bicycle': 0.0, 'occ/free': 10.0}),
        untrained=dict(counts, **{'occ/car': 0.2, 'occ/road': 40.0,
                                  'occ/bicycle': 0.0, 'occ/free': 50.0}))
    assert demo.unlearned_large_classes(row) == 'road'
    row['metrics']['occ/road'] = 45.0
    assert demo.unlearned_large_classes(row) == 'none'
