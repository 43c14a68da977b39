"""No README, doc, config, code comment or docstring cites our tracker.

Users of the library cannot open our internal issue tracker, so a
reference such as "issue N", "stop N" or "lease N" tells them nothing.
Say what and when instead: the date (YYYY-MM-DD) and / or the short commit
hash of the change or measurement (``git log -S'<text>'`` finds it), or
the machine and date of a GPU run. Lines that name another project's
issues (GitHub, mmdet3d, mmengine, mmcv, PyTorch, spconv) are theirs and
are kept, as the house grep keeps them:

    grep -rniE "\\b(issue|stop|lease)s? #?[0-9]+" README.md CHANGELOG.md \\
        docs projects tools demo configs \\
        --include=*.md --include=*.py --include=*.sh \\
        | grep -viE "github|mmdet3d|mmengine|mmcv|pytorch|spconv"
"""
import os
import os.path as osp
import re

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: The files and folders users read, one test case each.
PLACES = ('README.md', 'CHANGELOG.md', 'docs', 'projects', 'tools', 'demo',
          'configs')
SUFFIXES = ('.md', '.py', '.sh')
TRACKER = re.compile(r'\b(issue|stop|lease)s? #?[0-9]+', re.IGNORECASE)
OTHER_PROJECTS = re.compile(r'github|mmdet3d|mmengine|mmcv|pytorch|spconv',
                            re.IGNORECASE)


def _files(place):
    """The .md, .py and .sh files of ``place`` (a file or a folder)."""
    path = osp.join(ROOT, place)
    if osp.isfile(path):
        return [path]
    found = []
    for folder, subfolders, names in os.walk(path):
        subfolders[:] = sorted(d for d in subfolders if d != '__pycache__')
        found += [
            osp.join(folder, name) for name in sorted(names)
            if name.endswith(SUFFIXES)
        ]
    return found


def tracker_references(place):
    """Every line of ``place`` that cites the tracker.

    Args:
        place (str): A file or folder relative to the repository root.

    Returns:
        list[str]: ``'path:line: text'`` for each line the house grep
        prints.
    """
    hits = []
    for path in _files(place):
        with open(path, encoding='utf-8') as f:
            for number, line in enumerate(f, 1):
                if TRACKER.search(line) and not OTHER_PROJECTS.search(line):
                    hits.append(f'{osp.relpath(path, ROOT)}:{number}: '
                                f'{line.strip()}')
    return hits


def test_the_pattern_finds_what_the_grep_finds(tmp_path):
    """Caught: "issue 45", "Issue 14's stop 39", "stops 33-34", "lease 4",
    "issues #12"; kept: "issue 4172 of mmdet3d" (another project), "the
    fourth lease", "stop-35" (no number after a space) and "tissue 3" (no
    word boundary)."""
    caught = ['AMP trains (issue 45)', "Issue 14's stop 39 made",
              '(stops 33-34)', 'lease 4', 'see issues #12']
    kept = ['issue 4172 of mmdet3d', 'the fourth lease', 'the stop-35 rows',
            'tissue 3']
    assert all(TRACKER.search(text) for text in caught)
    assert not any(
        TRACKER.search(text) and not OTHER_PROJECTS.search(text)
        for text in kept)


@pytest.mark.parametrize('place', PLACES)
def test_no_tracker_numbers(place):
    """``place`` names no issue, stop or lease by its tracker number."""
    assert osp.exists(osp.join(ROOT, place)), place
    hits = tracker_references(place)
    assert hits == [], (
        f'{len(hits)} line(s) cite the internal tracker, which users cannot '
        'see; say what and when (date, commit) instead:\n' + '\n'.join(hits))
