"""tools/analysis_tools/graph_breaks.py on the tiny SDG-KL config: its
prediction traces as one graph on the path compiled code takes, while
the CPU's path (data-dependent selections) breaks; the JSON holds what
was returned (the counting itself: tests/occ_common/analysis/
test_compile_check.py)."""
import json

import pytest

from projects.occ_common.testing.tool_logs import load_tool

CONFIG = 'configs/sdg_occ/sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py'


@pytest.mark.slow
def test_sdg_kl_prediction_has_no_graph_break(tmp_path, capsys):
    """Compiled code (the GPU's path): 0 breaks in 1 graph, and a second
    point count compiles nothing. The CPU's path of the same model still
    breaks (its compactions), which is what the compiled path avoids."""
    tool = load_tool('tools/analysis_tools/graph_breaks.py')
    out = tmp_path / 'breaks.json'
    report = tool.main([CONFIG, '--num-points', '500', '--recompile',
                        '--json', str(out)])
    predict, = report['phases']
    assert (predict['breaks'], predict['graphs']) == (0, 1)
    assert predict['recompiles'] == 0 and predict['sites'] == []
    assert json.loads(out.read_text())['phases'][0]['breaks'] == 0
    assert 'predict: 0 graph breaks, 1 graphs' in capsys.readouterr().out
    cpu, = tool.main([CONFIG, '--num-points', '500',
                      '--cpu-path'])['phases']
    assert cpu['breaks'] > 0
    assert sum(site['count'] for site in cpu['sites']) == cpu['breaks']
    assert all(':' in site['location'] for site in cpu['sites'])
