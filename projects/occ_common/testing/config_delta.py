"""What a config changes in the model of the config it builds on.

The configs are deltas: a dataset config sets the coupled values on the
model base, an ablation one knob of a paper config. The project tests
compare each delta with its parent through :func:`model_delta` and allow
only the keys the delta documents, and check with
:func:`coupled_value_mismatches` that the coupled values are the dataset
base's.
"""
from typing import Any, Dict, List, Set

from mmengine.config import Config


def flatten(obj: Any, prefix: str = '') -> Dict[str, Any]:
    """``{'a.b[0].c': value}`` of a nested config.

    Args:
        obj (Any): A config value (dicts and lists are walked; a list of
            plain values is one leaf).
        prefix (str): Key of ``obj``. Defaults to ''.

    Returns:
        dict: Dotted key -> leaf value.
    """
    if isinstance(obj, dict):
        out = {}
        for key, value in obj.items():
            out.update(flatten(value, f'{prefix}.{key}' if prefix else key))
        return out
    if isinstance(obj, (list, tuple)) and any(
            isinstance(v, (dict, list, tuple)) for v in obj):
        out = {}
        for i, value in enumerate(obj):
            out.update(flatten(value, f'{prefix}[{i}]'))
        return out
    return {prefix: obj}


def model_delta(parent: str, child: str) -> Set[str]:
    """Keys of ``model`` whose values differ between two config files.

    A sub-config set to None (``loss_depth=None``) counts as its own key
    rather than as each of the keys it removes.

    Args:
        parent (str): Config file the child builds on.
        child (str): Config file.

    Returns:
        set[str]: Dotted keys, e.g. ``{'tpv_fusion.num_groups'}``.
    """
    a = flatten(Config.fromfile(parent).to_dict()['model'])
    b = flatten(Config.fromfile(child).to_dict()['model'])
    keys = set()
    for key in a.keys() | b.keys():
        if a.get(key) == b.get(key):
            continue
        removed = [p for p in _prefixes(key) if b.get(p, ...) is None]
        keys.add(removed[0] if removed else key)
    return keys


def _prefixes(key: str):
    parts = key.split('.')
    return ['.'.join(parts[:i]) for i in range(1, len(parts))]


def coupled_value_mismatches(cfg: Config, project: str) -> List[str]:
    """Where a model config does not take its coupled values from its
    dataset base.

    Args:
        cfg (Config): A loaded model config (dataset base included).
        project (str): ``'occ_cyl'`` or ``'sdg_occ'``: the package its
            ``custom_imports`` must add to ``projects.occ_common``.

    Returns:
        list[str]: One line per mismatch; empty when the grid, classes,
        empty label and supervision mask are the dataset's (Occ3D: label
        'free', camera-mask loss as its metric; SurroundOcc: 'empty').
    """
    model = cfg.model
    empty = 'free' if cfg.occ_format == 'occ3d' else 'empty'
    evaluators = cfg.val_evaluator if isinstance(
        cfg.val_evaluator, list) else [cfg.val_evaluator]
    voxel_metric = next(e for e in evaluators if e.type == 'OccupancyMetric')
    # A config scored with RayIoU trains on whole grids (SparseOcc's
    # advice for a fair RayIoU), whatever mask its voxel metric uses.
    ray_scored = any(e.type == 'OccRayIoUMetric' for e in evaluators)
    expected = dict(
        point_cloud_range=cfg.point_cloud_range,
        voxel_size=cfg.voxel_size,
        num_classes=len(cfg.class_names),
        empty_index=cfg.class_names.index(empty),
        loss_mask_key='mask_camera'
        if voxel_metric.use_camera_mask and not ray_scored else None)
    out = [
        f'model.{key} = {model.get(key)!r}, dataset: {value!r}'
        for key, value in expected.items() if model.get(key) != value
    ]
    imports = ['projects.occ_common', f'projects.{project}']
    if cfg.custom_imports.get('imports') != imports:
        out.append(f'custom_imports {cfg.custom_imports} != {imports}')
    return out
