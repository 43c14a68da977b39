"""docs/robustness.md lists every condition with the levels, scale and
source the code applies."""
import os.path as osp

from projects.occ_common.testing.tool_logs import REPO_ROOT
from projects.occ_common.transforms.corruptions.conditions import (CONDITIONS,
                                                                   levels_text)


def test_docs_table_is_the_code():
    with open(osp.join(REPO_ROOT, 'docs', 'robustness.md')) as f:
        rows = {line.split('|')[1].strip(' `'): line
                for line in f if line.startswith('| `')}
    for name, condition in CONDITIONS.items():
        expected = (f'| `{name}` | {condition.family} | {condition.scale} | '
                    f'{levels_text(condition)} | {condition.source} |')
        assert rows.get(name, '').strip() == expected, name


def test_levels_text():
    assert levels_text(CONDITIONS['pixelate']) == \
        '0.6, 0.5, 0.4, 0.3, 0.25'
    assert levels_text(CONDITIONS['spatial_misalignment']).startswith(
        '(0.3, 0.07), (0.6, 0.14)')
