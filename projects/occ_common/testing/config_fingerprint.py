"""Fingerprints of the models that the configs build.

A fingerprint records what a refactoring of the configs or of the model code
must not change by accident: the parameter count, every state-dict entry
with its shape and the parameters that start frozen (``requires_grad``
False, e.g. ResNet's ``frozen_stages``). The entries are kept as a SHA-256
digest per top-level child of the detector, so that the fixture stays small
and a mismatch still names the part that changed.

``tests/test_all_configs.py`` rebuilds every config and compares it with the
committed fixture ``tests/data/config_fingerprints.json``. After a change
that is *meant* to change a model (a new ablation config, a paper fix),
regenerate the fixture and commit it together with the change::

    python -m projects.occ_common.testing.config_fingerprint --write

Running it without ``--write`` prints the configs whose models differ.
"""
import argparse
import glob
import hashlib
import json
import os.path as osp
import sys
from typing import Dict, List, Optional

from torch import nn

from ..analysis.tool_runs import REPO_ROOT

FIXTURE = osp.join(REPO_ROOT, 'tests', 'data', 'config_fingerprints.json')


def config_paths(root: str = REPO_ROOT) -> List[str]:
    """Every buildable config: ``configs/**/*.py`` outside ``_base_``.

    Args:
        root (str): Repository root. Defaults to this checkout.

    Returns:
        list[str]: Paths relative to ``root``, sorted.
    """
    paths = glob.glob(osp.join(root, 'configs', '**', '*.py'), recursive=True)
    return sorted(
        osp.relpath(p, root) for p in paths
        if '_base_' not in osp.relpath(p, root).split(osp.sep))


def _digest(lines: List[str]) -> str:
    return hashlib.sha256('\n'.join(lines).encode()).hexdigest()[:16]


def model_fingerprint(model: nn.Module) -> Dict:
    """Parameter count, state-dict entries and frozen parameters.

    Args:
        model (nn.Module): A built detector.

    Returns:
        dict: ``params`` (int), ``state_dict_entries`` (int) and, per
        top-level child that holds state (``''`` for the detector's own
        parameters and buffers), ``params``, ``entries`` and ``digest`` of
        its sorted ``"key shape"`` lines, frozen parameters marked.
    """
    frozen = {n for n, p in model.named_parameters() if not p.requires_grad}
    lines: Dict[str, List[str]] = {}
    for key, value in model.state_dict().items():
        shape = 'x'.join(str(s) for s in value.shape)
        mark = ' frozen' if key in frozen else ''
        lines.setdefault(key.split('.')[0] if '.' in key else '',
                         []).append(f'{key} {shape}{mark}')
    counts: Dict[str, int] = {}
    for name, param in model.named_parameters():
        top = name.split('.')[0] if '.' in name else ''
        counts[top] = counts.get(top, 0) + param.numel()
    modules = {
        top: dict(
            params=counts.get(top, 0),
            entries=len(entries),
            digest=_digest(sorted(entries)))
        for top, entries in sorted(lines.items())
    }
    return dict(
        params=sum(p.numel() for p in model.parameters()),
        state_dict_entries=sum(len(v) for v in lines.values()),
        modules=modules)


def build_model(path: str) -> nn.Module:
    """Build a config's model as the Runner would (default scope set).

    Args:
        path (str): Config file.

    Returns:
        nn.Module: The model, initialised by its constructors only.
    """
    from mmdet3d.registry import MODELS
    from mmdet3d.utils import register_all_modules
    from mmengine.config import Config
    register_all_modules()  # the Runner's default_scope mmdet3d
    cfg = Config.fromfile(path)
    return MODELS.build(cfg.model)


def fingerprints(paths: Optional[List[str]] = None,
                 root: str = REPO_ROOT) -> Dict[str, Dict]:
    """Fingerprint of every config.

    Args:
        paths (list[str], optional): Configs relative to ``root``.
            Defaults to :func:`config_paths`.
        root (str): Repository root. Defaults to this checkout.

    Returns:
        dict: Config path -> :func:`model_fingerprint`.
    """
    paths = config_paths(root) if paths is None else paths
    return {
        p: model_fingerprint(build_model(osp.join(root, p)))
        for p in paths
    }


def differences(expected: Dict, actual: Dict) -> List[str]:
    """Human-readable differences between two fingerprints of one model.

    Args:
        expected (dict): From the fixture.
        actual (dict): From :func:`model_fingerprint`.

    Returns:
        list[str]: One line per differing child or total; empty if equal.
    """
    out = []
    for key in ('params', 'state_dict_entries'):
        if expected.get(key) != actual.get(key):
            out.append(f'{key}: {expected.get(key)} -> {actual.get(key)}')
    old, new = expected.get('modules', {}), actual.get('modules', {})
    for name in sorted(old.keys() | new.keys()):
        if old.get(name) != new.get(name):
            out.append(f'child {name or "(own)"!r}: {old.get(name)} -> '
                       f'{new.get(name)}')
    return out


def main(argv: Optional[List[str]] = None) -> int:
    """Compare the configs with the fixture, or rewrite it (``--write``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument(
        '--write', action='store_true', help=f'rewrite {FIXTURE}')
    parser.add_argument('--fixture', default=FIXTURE)
    args = parser.parse_args(argv)
    current = fingerprints()
    if args.write:
        with open(args.fixture, 'w') as f:
            json.dump(current, f, indent=1, sort_keys=True)
            f.write('\n')
        print(f'wrote {len(current)} fingerprints to {args.fixture}')
        return 0
    with open(args.fixture) as f:
        stored = json.load(f)
    changed = 0
    for path in sorted(stored.keys() | current.keys()):
        if path not in current or path not in stored:
            print(f'{path}: only in the '
                  f'{"fixture" if path in stored else "tree"}')
            changed += 1
            continue
        lines = differences(stored[path], current[path])
        if lines:
            changed += 1
            print(f'{path}:\n  ' + '\n  '.join(lines))
    print(f'{changed} of {len(current)} configs differ from the fixture')
    return 1 if changed else 0


if __name__ == '__main__':
    sys.exit(main())
