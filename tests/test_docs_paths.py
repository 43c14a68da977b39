"""Every path, link and command that README.md and docs/ show exists.

A user copies commands from the front door: a moved tool, a renamed
config or a flag that a tool no longer takes must fail here, not on their
machine. Checked in README.md, docs/**/*.md and the projects' READMEs:

- each repository path in the text (``tools/...``, ``configs/...``,
  ``projects/...``, ``demo/...``, ``docs/...``, ``tests/...``) exists;
  placeholders (``<...>``, ``*``, ``…``, ``$VAR``) and another project's
  files (``${MMDET3D}/tools/...``) are not paths of ours;
- each relative Markdown link resolves, and its ``#anchor`` names a heading
  of the target (GitHub's slugs);
- each ``--flag`` given to one of our Python tools in a command line is an
  option that tool's argparse declares.
"""
import glob
import os.path as osp
import re

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
DOCS = sorted(
    osp.relpath(p, ROOT)
    for pattern in ('README.md', 'docs/**/*.md', 'projects/*/README.md')
    for p in glob.glob(osp.join(ROOT, pattern), recursive=True))

PATH = re.compile(r'(?<![\w/.$}-])((?:tools|configs|projects|demo|docs|tests)'
                  r'/[\w/.<>*…{}$-]*)')
LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')
COMMAND = re.compile(r'(?:python\S*|bash)\s+((?:tools|demo)/[\w/]+\.(?:py|sh))'
                     r'((?:[ \t]+(?:\\\n)?[^\n|`]*)*)')


def _read(doc):
    with open(osp.join(ROOT, doc), encoding='utf-8') as f:
        return f.read()


def _slug(heading):
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r'[`*]', '', heading.strip().lower())
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


def _anchors(path):
    return {
        _slug(m.group(1))
        for m in re.finditer(r'^#+\s+(.*)$', _read(path), flags=re.M)
    }


def test_slug_matches_github():
    """'## Installation on GPU' -> installation-on-gpu; backticks and
    punctuation drop, underscores stay: '## `--cfg-options`, typos' ->
    --cfg-options-typos, '## `visualize_occ.py`' -> visualize_occpy."""
    assert _slug('Installation on GPU') == 'installation-on-gpu'
    assert _slug('`visualize_occ.py`') == 'visualize_occpy'
    assert _slug('`--cfg-options`, typos') == '--cfg-options-typos'


def test_the_documents_are_found():
    assert {'README.md', 'docs/get_started.md', 'docs/reports/README.md',
            'projects/occ_cyl/README.md'} <= set(DOCS)


def test_readme_fits_on_a_screen():
    """The front door stays short: at most 200 lines."""
    assert len(_read('README.md').splitlines()) <= 200


@pytest.mark.parametrize('doc', DOCS)
def test_repository_paths_exist(doc):
    missing = []
    for match in PATH.finditer(_read(doc)):
        path = match.group(1).rstrip('.,:;')
        if re.search(r'[<>*…{}$]', path):
            continue
        if not osp.exists(osp.join(ROOT, path)):
            missing.append(path)
    assert missing == [], f'{doc} names paths that do not exist'


@pytest.mark.parametrize('doc', DOCS)
def test_relative_links_resolve(doc):
    broken = []
    for target in LINK.findall(_read(doc)):
        if re.match(r'[a-z]+:', target):
            continue
        file_part, _, anchor = target.partition('#')
        path = (osp.normpath(osp.join(osp.dirname(doc), file_part))
                if file_part else doc)
        full = osp.join(ROOT, path)
        if not osp.exists(full):
            broken.append(target)
        elif anchor and path.endswith('.md') and anchor not in _anchors(path):
            broken.append(target)
    assert broken == [], f'{doc} has broken links'


def _declared_options(script):
    """The ``--options`` a tool's source declares (argparse strings), with
    those of the project's modules it imports (shared parsers such as
    ``add_split_arguments``)."""
    sources = [_read(script)]
    for module in re.findall(r'^from (projects\.[\w.]+) import', sources[0],
                             flags=re.M):
        path = module.replace('.', '/') + '.py'
        if osp.isfile(osp.join(ROOT, path)):
            sources.append(_read(path))
    options = {'--help'}
    for source in sources:
        options |= set(re.findall(r"""['"](--[\w-]+)['"]""", source))
    return options


@pytest.mark.parametrize('doc', DOCS)
def test_command_flags_are_declared(doc):
    """``python tools/train.py CONFIG --resume`` needs '--resume' in
    tools/train.py; shell scripts pass their extra ARGS to train.py or
    test.py, which are checked where they are called directly."""
    unknown = []
    for match in COMMAND.finditer(_read(doc)):
        script, rest = match.group(1), match.group(2)
        assert osp.isfile(osp.join(ROOT, script)), script
        if not script.endswith('.py'):
            continue
        declared = _declared_options(script)
        for flag in re.findall(r'(?<![\w-])(--[a-z][\w-]*)', rest):
            if flag not in declared:
                unknown.append(f'{script} {flag}')
    assert unknown == [], f'{doc} passes options the tools do not take'
