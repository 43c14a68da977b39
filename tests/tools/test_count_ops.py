"""tools/analysis_tools/count_ops.py on the tiny SDG-Fusion config: the
rows add up to the totals, the batch sizes are all counted, the JSON
holds what was printed (the counting itself:
tests/occ_common/analysis/test_op_counting.py)."""
import json

from projects.occ_common.testing.tool_logs import load_tool

CONFIG = 'configs/sdg_occ/sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py'


def test_prediction_counts_add_up(tmp_path, capsys):
    out = tmp_path / 'ops.json'
    report = load_tool('tools/analysis_tools/count_ops.py').main([
        CONFIG, '--batch', '1', '2', '--num-points', '500', '--json',
        str(out)
    ])
    assert report['mode'] == 'predict' and set(report['batches']) == {1, 2}
    for entry in report['batches'].values():
        rows, totals = entry['rows'], entry['totals']
        assert sum(r['launches'] for r in rows) == totals['launches'] > 100
        assert sum(r['syncs'] for r in rows) == totals['syncs']
        # A prediction has no backward (``other``: test_step's own copies
        # outside the model's forward).
        assert {r['phase'] for r in rows} <= {'forward', 'other'}
        modules = {r['module'] for r in rows}
        assert {'img_backbone', 'fusion', 'lidar_encoder'} <= modules
    saved = json.loads(out.read_text())
    assert saved['batches']['2']['totals'] == report['batches'][2]['totals']
    text = capsys.readouterr().out
    assert 'predict, batch 2' in text and 'batch 2 / batch 1: launches' in text
