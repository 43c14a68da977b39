"""Checked loading of pretrained weights into parts of a detector.

Both detectors list the parts that may start from pretrained weights in
their ``pretrained`` argument (see :class:`BaseOccDetector`), one named
entry per part::

    pretrained=dict(
        img_backbone=dict(
            module='img_encoder.backbone',    # attribute path in the model
            checkpoint='torchvision://resnet50',  # None: train from scratch
            prefix=None,          # e.g. 'backbone.' for a detector's file
            style='pytorch',      # the backbone style and image
                                  # normalisation the weights need
            ignore=[r'^fc\\.'],    # checkpoint keys not to load (reported)
            allow_missing=[],     # module keys the file may lack
            key_map=[],           # (pattern, replacement) renames of the
                                  # file's keys, e.g. another codebase's
            tolerance=0))         # further differing keys accepted

mmengine's ``init_cfg=dict(type='Pretrained')`` loads with
``strict=False``: a checkpoint of another layout "loads" with hundreds of
unexpected keys and a single warning (FCOS3D's ResNet-101-DCN into a
ResNet-50: 358), and mmdet's Swin cannot load ImageNet weights into a
plane encoder at all (its patch embedding takes 128 channels in 2 x 2
patches, not RGB in 4 x 4, and ``load_state_dict`` raises on the shape).
Here instead:

* without a checkpoint the part keeps its initialisation and must train
  normally: frozen stages, frozen BN statistics or any parameter that
  does not train (``frozen_stages >= 0``, ``norm_eval=True``, a
  ``norm_cfg`` with ``requires_grad=False``) are refused, they would
  freeze random weights;
* with one, the file's keys are renamed by ``key_map`` (after ``prefix``:
  each ``(pattern, replacement)`` pair is applied with :func:`re.sub`, in
  order, so a checkpoint of another codebase whose layers carry other
  names can load; two keys renamed alike are refused), then keys and
  shapes are compared. Keys matching
  ``ignore`` are not loaded and reported (a classifier head, a patch
  embedding of another shape), module keys matching ``allow_missing`` keep
  their initialisation and are reported; any other missing, unexpected or
  mis-shaped key counts against ``tolerance``, and beyond it the load is
  refused with an error naming the file, the part and the first differing
  keys. BN's ``num_batches_tracked`` counters are not weights and are never
  counted (torchvision's files omit them);
* ``style`` ties the weights to the backbone's ``style`` and to the data
  preprocessor's normalisation (:data:`STYLE_NORMALIZATION`): a caffe-style
  ResNet expects BGR images minus the BGR means with unit std and puts the
  stride in its 1x1 conv; a pytorch-style one (torchvision, mmdet's
  ``torchvision://``) expects RGB images standardised by the ImageNet std;
* official Swin files (``layers.*`` keys) are converted with mmdet's
  ``swin_converter`` when the part is an mmdet ``SwinTransformer``;
* ``torchvision://NAME`` and ``http(s)://`` checkpoints are fetched into
  torch's hub cache (``$TORCH_HOME/hub/checkpoints``) without torchvision,
  and every file is read with the library's restricted unpickler
  (:func:`~projects.occ_common.fileio.load_checkpoint_file`): tensors and
  containers only, nothing in the file can run.
"""
import logging
import os.path as osp
import re
from typing import Dict, List, Mapping, Optional, Tuple

from mmengine.logging import print_log
from torch import Tensor, nn

from ..fileio.hub_cache import cached_download, torchvision_url
from ..fileio.safe_pickle import load_checkpoint_file
from ..fileio.state_dict import compare_state_dicts as _compare
from ..fileio.state_dict import unwrap_state_dict

#: The data preprocessor's normalisation each ResNet style's weights were
#: trained with (mmdet's conventions; images are loaded as BGR).
STYLE_NORMALIZATION = {
    'pytorch':
    dict(
        mean=(123.675, 116.28, 103.53),
        std=(58.395, 57.12, 57.375),
        bgr_to_rgb=True),
    'caffe':
    dict(mean=(103.53, 116.28, 123.675), std=(1.0, 1.0, 1.0),
         bgr_to_rgb=False),
}

_DEFAULTS = dict(
    checkpoint=None,
    prefix=None,
    style=None,
    ignore=(),
    allow_missing=(),
    key_map=(),
    tolerance=0)
_SHOWN = 10  # keys named in a message


class PretrainedMismatchError(ValueError):
    """A checkpoint whose layout does not fit the part it should load into.
    """


def check_entries(pretrained: Optional[Mapping]) -> Dict[str, dict]:
    """Validate the ``pretrained`` entries of a detector config.

    Args:
        pretrained (Mapping, optional): Entry name -> dict with ``module``
            and the optional keys of the module docstring, or None to drop
            the entry (a config without that part).

    Returns:
        dict[str, dict]: Entries with every key filled in.

    Raises:
        ValueError: Naming the entry and the bad key or value.
    """
    entries = {}
    for name, entry in (pretrained or {}).items():
        if entry is None:
            continue  # dropped, e.g. by a config that removes the part
        if not isinstance(entry, Mapping) or 'module' not in entry:
            raise ValueError(f'pretrained.{name} must be a dict with a '
                             f'"module" path, got {entry!r}')
        unknown = set(entry) - set(_DEFAULTS) - {'module'}
        if unknown:
            raise ValueError(f'pretrained.{name}: unknown keys '
                             f'{sorted(unknown)}; allowed: module, '
                             f'{", ".join(_DEFAULTS)}')
        full = dict(_DEFAULTS, **entry)
        if full['style'] not in (None, *STYLE_NORMALIZATION):
            raise ValueError(f'pretrained.{name}: style must be one of '
                             f'{sorted(STYLE_NORMALIZATION)} or None, got '
                             f'{full["style"]!r}')
        if int(full['tolerance']) != full['tolerance'] or \
                full['tolerance'] < 0:
            raise ValueError(f'pretrained.{name}: tolerance must be a '
                             f'count >= 0, got {full["tolerance"]!r}')
        for key in ('ignore', 'allow_missing'):
            if isinstance(full[key], str):
                raise ValueError(f'pretrained.{name}.{key} must be a list of '
                                 f'patterns, got the string {full[key]!r}')
            full[key] = tuple(re.compile(p) for p in full[key])
        full['key_map'] = _check_key_map(name, full['key_map'])
        entries[name] = full
    return entries


def _check_key_map(name: str,
                   key_map) -> Tuple[Tuple[re.Pattern, str], ...]:
    """Compiled ``(pattern, replacement)`` pairs of an entry's
    ``key_map``."""
    pairs = []
    for pair in key_map:
        if isinstance(pair, str) or len(pair) != 2 or not all(
                isinstance(p, str) for p in pair):
            raise ValueError(f'pretrained.{name}.key_map must be a list of '
                             f'(pattern, replacement) string pairs, got '
                             f'{pair!r}')
        pairs.append((re.compile(pair[0]), pair[1]))
    return tuple(pairs)


def rename_keys(state: Mapping[str, Tensor], key_map, where: str
                ) -> Dict[str, Tensor]:
    """A checkpoint's tensors under the names ``key_map`` gives them.

    Args:
        state (Mapping[str, Tensor]): Key -> tensor.
        key_map (Sequence): Compiled ``(pattern, replacement)`` pairs,
            applied with :func:`re.sub` in order.
        where (str): The entry and file, for messages.

    Returns:
        dict[str, Tensor]: Renamed key -> tensor.

    Raises:
        PretrainedMismatchError: When two keys get the same name.
    """
    renamed = {}
    for key, value in state.items():
        new = key
        for pattern, replacement in key_map:
            new = pattern.sub(replacement, new)
        if new in renamed:
            raise PretrainedMismatchError(
                f'{where}: key_map gives two of the file\'s keys the name '
                f'{new!r} (one of them {key!r})')
        renamed[new] = value
    return renamed


def resolve_checkpoint(checkpoint: str) -> str:
    """Local file of a checkpoint path, ``torchvision://`` name or URL.

    URLs are downloaded once into ``torch.hub.get_dir()/checkpoints``; a
    file already there is used as is (so a file copied there by hand works
    offline).

    Args:
        checkpoint (str): Path, ``torchvision://NAME`` or ``http(s)://``.

    Returns:
        str: Path of a local file (not checked for existence).

    Raises:
        ValueError: For an unknown ``torchvision://`` name.
        RuntimeError: When a download fails, naming the URL and where to
            put the file instead.
    """
    if checkpoint.startswith('torchvision://'):
        return cached_download(torchvision_url(checkpoint), name=checkpoint)
    if checkpoint.startswith(('http://', 'https://')):
        return cached_download(checkpoint)
    return osp.expanduser(checkpoint)


def checkpoint_state_dict(path: str,
                          prefix: Optional[str] = None) -> Dict[str, Tensor]:
    """The tensors of a checkpoint file, unwrapped and prefix-stripped.

    Args:
        path (str): Local checkpoint file (read weights-only).
        prefix (str, optional): Keep only keys starting with it, stripped
            (``'backbone.'`` for a detector's file). Defaults to None.

    Returns:
        dict[str, Tensor]: Key -> tensor.
    """
    try:
        state = unwrap_state_dict(
            load_checkpoint_file(path, map_location='cpu'), path, prefix)
    except ValueError as err:
        raise PretrainedMismatchError(str(err)) from None
    return {k: v for k, v in state.items() if isinstance(v, Tensor)}


def _is_swin(module: nn.Module) -> bool:
    """An mmdet Swin, or a subclass such as RecomputedSwinTransformer."""
    from mmdet.models.backbones import SwinTransformer
    return isinstance(module, SwinTransformer)


def _prefix_hint(unexpected: List[str], own: Mapping) -> str:
    """Suggest ``prefix`` when the unexpected keys are the module's own
    keys under one leading component."""
    heads = {k.split('.', 1)[0] for k in unexpected if '.' in k}
    for head in heads:
        inner = [k.split('.', 1)[1] for k in unexpected
                 if k.startswith(head + '.')]
        if inner and sum(k in own for k in inner) >= len(own) // 2:
            return f' The keys look nested: try prefix={head + "."!r}.'
    return ''


def compare_state_dicts(own: Mapping[str, Tensor],
                        theirs: Mapping[str, Tensor], entry: dict
                        ) -> Tuple[Dict[str, Tensor], Dict[str, list]]:
    """Split a checkpoint's tensors into what loads and what differs.

    Args:
        own (Mapping[str, Tensor]): The module's state dict.
        theirs (Mapping[str, Tensor]): The checkpoint's tensors.
        entry (dict): A checked entry (``ignore``, ``allow_missing``).

    Returns:
        tuple: The tensors to load, and lists of keys: ``ignored``
        (checkpoint keys matching ``ignore``), ``allowed_missing``,
        ``unexpected``, ``missing`` and ``shape`` (``key``, checkpoint
        shape, module shape).
    """
    return _compare(own, theirs, entry['ignore'], entry['allow_missing'])


def check_style(module: nn.Module, name: str, style: Optional[str],
                data_preprocessor: Optional[nn.Module]) -> None:
    """Refuse weights of one style with a backbone or normalisation of
    another.

    Args:
        module (nn.Module): The part the weights load into.
        name (str): Entry name, for messages.
        style (str, optional): ``'pytorch'`` or ``'caffe'``; None checks
            nothing.
        data_preprocessor (nn.Module, optional): The detector's
            ``Det3DDataPreprocessor``.

    Raises:
        ValueError: Naming the entry, what differs and the expected values.
    """
    if style is None:
        return
    own_style = getattr(module, 'style', style)
    if own_style != style:
        raise ValueError(f'pretrained.{name}: {style}-style weights into a '
                         f'{own_style}-style {type(module).__name__}; set '
                         f'the backbone\'s style={style!r}')
    if data_preprocessor is None or not hasattr(data_preprocessor, 'mean'):
        return
    want = STYLE_NORMALIZATION[style]
    mean = data_preprocessor.mean.flatten().tolist()
    std = data_preprocessor.std.flatten().tolist()
    swap = bool(getattr(data_preprocessor, '_channel_conversion', False))
    close = all(
        abs(a - b) < 1e-3 for a, b in zip(mean + std, want['mean'] +
                                          want['std']))
    if not (close and swap == want['bgr_to_rgb']):
        raise ValueError(
            f'pretrained.{name}: {style}-style weights need the data '
            f'preprocessor mean={list(want["mean"])}, '
            f'std={list(want["std"])}, bgr_to_rgb={want["bgr_to_rgb"]}; '
            f'it has mean={[round(v, 3) for v in mean]}, '
            f'std={[round(v, 3) for v in std]}, channel swap={swap}')


def _check_trains_normally(module: nn.Module, name: str) -> None:
    frozen = getattr(module, 'frozen_stages', -1)
    norm_eval = getattr(module, 'norm_eval', False)
    if frozen >= 0 or norm_eval:
        raise ValueError(
            f'pretrained.{name}: no checkpoint, but '
            f'{type(module).__name__} has frozen_stages={frozen}, '
            f'norm_eval={norm_eval}: that would freeze randomly initialised '
            'layers and BN statistics. Give the entry a checkpoint, or set '
            'frozen_stages=-1 and norm_eval=False to train it from scratch')
    fixed = [n for n, p in module.named_parameters() if not p.requires_grad]
    if fixed:
        raise ValueError(
            f'pretrained.{name}: no checkpoint, but {len(fixed)} parameters '
            f'of {type(module).__name__} do not train (first: {fixed[0]}; '
            'e.g. norm_cfg=dict(..., requires_grad=False)): they would '
            'stay at their initialisation. Give the entry a checkpoint, or '
            'let them train (norm_cfg requires_grad=True)')


def _describe(key, theirs: Mapping, own: Mapping) -> str:
    """``key (checkpoint shape, module shape)`` for a log line."""
    if not isinstance(key, str):
        return f'{key[0]} (file {key[1]}, module {key[2]})'
    shapes = [
        f'{where} {tuple(d[key].shape)}'
        for where, d in (('file', theirs), ('module', own)) if key in d
    ]
    return f'{key} ({", ".join(shapes)})'


def load_pretrained(module: nn.Module,
                    name: str,
                    entry: dict,
                    data_preprocessor: Optional[nn.Module] = None) -> dict:
    """Apply one checked ``pretrained`` entry to its part.

    Args:
        module (nn.Module): The part (``entry['module']`` of the model).
        name (str): Entry name, for messages.
        entry (dict): From :func:`check_entries`.
        data_preprocessor (nn.Module, optional): For the ``style`` check.

    Returns:
        dict: ``loaded`` (number of tensors) and the key lists of
        :func:`compare_state_dicts`; empty without a checkpoint.

    Raises:
        PretrainedMismatchError: When more keys differ than ``tolerance``.
        ValueError: From the style and from-scratch checks.
    """
    where = f'{entry["module"]} ({type(module).__name__})'
    if entry['checkpoint'] is None:
        _check_trains_normally(module, name)
        print_log(f'pretrained.{name}: no checkpoint, {where} trains from '
                  'its initialisation', logger='current')
        return {}
    check_style(module, name, entry['style'], data_preprocessor)
    path = resolve_checkpoint(entry['checkpoint'])
    theirs = checkpoint_state_dict(path, entry['prefix'])
    if entry['key_map']:
        theirs = rename_keys(theirs, entry['key_map'],
                             f'pretrained.{name} ({path})')
    if _is_swin(module) and any(k.startswith('layers.') for k in theirs):
        from mmdet.models.backbones.swin import swin_converter
        theirs = {
            k[len('backbone.'):]: v
            for k, v in swin_converter(theirs).items()
        }
        print_log(f'pretrained.{name}: converted the official Swin keys of '
                  f'{path}', logger='current')
    own = module.state_dict()
    load, report = compare_state_dicts(own, theirs, entry)
    differing = (len(report['unexpected']) + len(report['missing']) +
                 len(report['shape']))
    if differing > entry['tolerance'] or not load:
        shown = {
            k: v[:_SHOWN]
            for k, v in report.items()
            if k in ('unexpected', 'missing', 'shape') and v
        }
        raise PretrainedMismatchError(
            f'pretrained.{name}: checkpoint {path} does not fit {where}: '
            f'{len(report["unexpected"])} unexpected, '
            f'{len(report["missing"])} missing and {len(report["shape"])} '
            f'mis-shaped keys, tolerance {entry["tolerance"]}; first keys: '
            f'{shown}; {len(load)} tensors would load.'
            f'{_prefix_hint(report["unexpected"], own)} Is it the '
            'intended file? Its ignore / allow_missing patterns state which '
            'differences are expected.')
    module.load_state_dict(load, strict=False)
    print_log(
        f'pretrained.{name}: loaded {len(load)} tensors from {path} into '
        f'{where}', logger='current')
    for key, level, text in (
        ('ignored', logging.WARNING, 'not loaded (ignore patterns)'),
        ('allowed_missing', logging.INFO,
         'not in the file, left at their initialisation'),
        ('unexpected', logging.WARNING, 'unexpected, within tolerance'),
        ('missing', logging.WARNING, 'missing, within tolerance'),
        ('shape', logging.WARNING, 'mis-shaped, within tolerance'),
    ):
        if report[key]:
            detail = [_describe(k, theirs, own) for k in report[key]]
            print_log(
                f'pretrained.{name}: {len(detail)} keys {text}: '
                f'{", ".join(detail)}',
                logger='current',
                level=level)
    return dict(loaded=len(load), **report)
