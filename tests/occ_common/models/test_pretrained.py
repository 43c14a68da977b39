"""Tests of the checked pretrained-weight loading (issue 11 item 7, issue 15
item 2)."""
import logging

import pytest
import torch
from mmdet3d.registry import MODELS
from mmdet3d.utils import register_all_modules
from mmengine.logging import MMLogger

from projects.occ_common.fileio import UnsafeCheckpointError
from projects.occ_common.models.pretrained import (PretrainedMismatchError,
                                                   check_entries,
                                                   load_pretrained,
                                                   resolve_checkpoint)
from projects.occ_common.testing.imagenet_swin import official_swin_state

register_all_modules(init_default_scope=False)


def _resnet(depth=18, **kwargs):
    torch.manual_seed(0)
    cfg = dict(type='mmdet.ResNet', depth=depth, base_channels=4,
               out_indices=(3, ), norm_eval=False, init_cfg=None)
    cfg.update(kwargs)
    return MODELS.build(cfg)


def _entry(**kwargs):
    return check_entries(dict(img=dict(module='backbone', **kwargs)))['img']


def _torchvision_file(module, path, offset=1.0):
    """The module's own tensors shifted by ``offset``, plus an ImageNet
    classifier ``fc`` as in torchvision's files, without BN counters."""
    state = {k: v + offset if v.is_floating_point() else v
             for k, v in module.state_dict().items()
             if not k.endswith('num_batches_tracked')}
    state['fc.weight'] = torch.zeros(10, 32)
    state['fc.bias'] = torch.zeros(10)
    torch.save(state, path)
    return state


@pytest.fixture
def log_lines():
    """Messages the loader logs through the current MMLogger."""
    logger = MMLogger.get_current_instance()
    records = []
    handler = logging.Handler()
    handler.emit = lambda record: records.append(record.getMessage())
    logger.addHandler(handler)
    yield records
    logger.removeHandler(handler)


def test_checkpoint_of_the_same_layout_loads_and_reports(
        tmp_path, log_lines):
    """A torchvision-layout file of the same ResNet loads every tensor
    (the BN counters it lacks are not weights); the classifier fc.weight /
    fc.bias match the ignore pattern and are reported as not loaded."""
    net = _resnet()
    state = _torchvision_file(net, tmp_path / 'r18.pth')
    report = load_pretrained(
        net, 'img', _entry(checkpoint=str(tmp_path / 'r18.pth'),
                           ignore=[r'^fc\.']))
    assert report['ignored'] == ['fc.weight', 'fc.bias']
    assert report['missing'] == report['unexpected'] == []
    assert report['loaded'] == len(state) - 2
    torch.testing.assert_close(net.conv1.weight, state['conv1.weight'])
    torch.testing.assert_close(net.layer4[1].bn2.running_var,
                               state['layer4.1.bn2.running_var'])
    assert any('2 keys not loaded' in m and 'fc.weight (file (10, 32))' in m
               for m in log_lines)


def test_mismatching_checkpoint_is_refused_by_name(tmp_path):
    """A ResNet-34 file (3, 4, 6, 3 blocks) into a ResNet-18 (2 each): the
    extra blocks layer1.2, layer2.2, layer2.3, ... are unexpected keys; the
    error names the file, the part and the first of them, and nothing is
    loaded. With a tolerance above their count it loads."""
    r34 = _resnet(34)
    _torchvision_file(r34, tmp_path / 'r34.pth', offset=0.0)
    net = _resnet(18)
    before = net.conv1.weight.clone()
    entry = _entry(checkpoint=str(tmp_path / 'r34.pth'), ignore=[r'^fc\.'])
    with pytest.raises(PretrainedMismatchError) as err:
        load_pretrained(net, 'img', entry)
    message = str(err.value)
    assert 'pretrained.img: checkpoint' in message
    assert 'r34.pth does not fit backbone (ResNet)' in message
    assert "'layer1.2.conv1.weight'" in message
    assert 'tolerance 0' in message
    assert torch.equal(net.conv1.weight, before)
    extra = len([k for k in r34.state_dict()
                 if k not in net.state_dict()
                 and not k.endswith('num_batches_tracked')])
    loaded = load_pretrained(net, 'img', dict(entry, tolerance=extra))
    assert len(loaded['unexpected']) == extra
    torch.testing.assert_close(net.conv1.weight, r34.conv1.weight)


def test_detector_checkpoint_needs_its_prefix(tmp_path):
    """A detector's Runner checkpoint nests the backbone under
    'backbone.': without prefix it is refused with the hint, with
    prefix='backbone.' it loads."""
    net = _resnet()
    state = {f'backbone.{k}': v + 2 for k, v in net.state_dict().items()}
    state['neck.conv.weight'] = torch.zeros(1)
    torch.save(dict(state_dict=state, meta=dict(epoch=12)),
               tmp_path / 'det.pth')
    with pytest.raises(PretrainedMismatchError,
                       match="try prefix='backbone.'"):
        load_pretrained(net, 'img', _entry(checkpoint=str(tmp_path /
                                                          'det.pth')))
    load_pretrained(
        net, 'img',
        _entry(checkpoint=str(tmp_path / 'det.pth'), prefix='backbone.'))
    torch.testing.assert_close(net.conv1.weight,
                               state['backbone.conv1.weight'])
    with pytest.raises(PretrainedMismatchError, match="no key starting with"):
        load_pretrained(
            net, 'img',
            _entry(checkpoint=str(tmp_path / 'det.pth'), prefix='img.'))


def test_without_checkpoint_frozen_random_layers_are_refused():
    """No checkpoint: the part must train normally. frozen_stages=1 (a
    frozen random stem) or norm_eval=True (BN statistics that never
    update) are refused, naming both settings; frozen_stages=-1 with live
    BN passes and changes nothing."""
    with pytest.raises(ValueError, match='frozen_stages=1, norm_eval=True'):
        load_pretrained(_resnet(frozen_stages=1, norm_eval=True), 'img',
                        _entry())
    with pytest.raises(ValueError, match='norm_eval=True'):
        load_pretrained(_resnet(norm_eval=True), 'img', _entry())
    net = _resnet()
    before = {k: v.clone() for k, v in net.state_dict().items()}
    assert load_pretrained(net, 'img', _entry()) == {}
    assert all(torch.equal(before[k], v) for k, v in net.state_dict().items())


def test_style_must_agree_with_backbone_and_normalisation(tmp_path):
    """Caffe-style weights need a caffe-style ResNet and BGR means with
    unit std, no channel swap; the pytorch-style preprocessor of the
    configs (ImageNet RGB mean / std) is refused with both values named."""
    preprocessor = MODELS.build(
        dict(type='Det3DDataPreprocessor', mean=[123.675, 116.28, 103.53],
             std=[58.395, 57.12, 57.375], bgr_to_rgb=True))
    path = str(tmp_path / 'r18.pth')
    _torchvision_file(_resnet(style='caffe'), path)
    entry = _entry(checkpoint=path, style='caffe', ignore=[r'^fc\.'])
    with pytest.raises(ValueError, match="caffe-style weights into a "
                       "pytorch-style ResNet; set the backbone's "
                       "style='caffe'"):
        load_pretrained(_resnet(), 'img', entry, preprocessor)
    with pytest.raises(ValueError, match=r'mean=\[103.53, 116.28, 123.675\], '
                       r'std=\[1.0, 1.0, 1.0\], bgr_to_rgb=False; it has '
                       r'mean=\[123.675'):
        load_pretrained(_resnet(style='caffe'), 'img', entry, preprocessor)
    caffe = MODELS.build(
        dict(type='Det3DDataPreprocessor', mean=[103.53, 116.28, 123.675],
             std=[1.0, 1.0, 1.0], bgr_to_rgb=False))
    assert load_pretrained(_resnet(style='caffe'), 'img', entry,
                           caffe)['loaded'] > 0


def _swin(in_channels, patch_size, kind='mmdet.SwinTransformer'):
    torch.manual_seed(0)
    return MODELS.build(
        dict(type=kind, in_channels=in_channels,
             embed_dims=8, depths=(1, 2), num_heads=(1, 2), window_size=2,
             patch_size=patch_size, strides=(patch_size, 2),
             out_indices=(0, 1), pretrain_img_size=8))


SWIN_ENTRY = dict(
    ignore=[r'^patch_embed\.projection\.', r'^norm\.', r'\.attn_mask$'],
    allow_missing=[r'^norm[0-3]\.'])


def _official_swin_file(path):
    """An ImageNet Swin (RGB, 4 x 4 patches) in the official layout, its
    values offset by 0.5 from the module's (so a load is visible), with a
    10-class head."""
    state = official_swin_state(
        _swin(3, 4), num_classes=10,
        value=lambda key, v: v + 0.5 if v.is_floating_point() else v)
    torch.save(dict(model=state), path)
    return state


@pytest.mark.parametrize('kind', [
    'mmdet.SwinTransformer', 'RecomputedSwinTransformer'])
def test_swin_imagenet_weights_load_all_but_the_patch_embedding(
        kind, tmp_path, log_lines):
    """Official ImageNet Swin weights into the plane encoder's Swin (128
    channels in the paper, 5 here, 2 x 2 patches): the keys are converted
    (mmdet's swin_converter), everything loads except the patch
    embedding's projection (file (8, 3, 4, 4), module (8, 5, 2, 2)), which
    is reported, and the per-level norms the classifier does not have. The
    patch embedding keeps its initialisation."""
    path = str(tmp_path / 'swin.pth')
    official = _official_swin_file(path)
    plane_swin = _swin(5, 2, kind)
    projection = plane_swin.patch_embed.projection.weight.clone()
    report = load_pretrained(plane_swin, 'tpv',
                             _entry(checkpoint=path, **SWIN_ENTRY))
    assert sorted(report['ignored']) == [
        'norm.bias', 'norm.weight', 'patch_embed.projection.bias',
        'patch_embed.projection.weight', 'stages.0.blocks.1.attn_mask'
    ]
    assert report['allowed_missing'] == [
        'norm0.weight', 'norm0.bias', 'norm1.weight', 'norm1.bias'
    ]
    assert report['missing'] == report['unexpected'] == report['shape'] == []
    assert torch.equal(plane_swin.patch_embed.projection.weight, projection)
    torch.testing.assert_close(
        plane_swin.stages[1].blocks[1].attn.w_msa.qkv.weight,
        official['layers.1.blocks.1.attn.qkv.weight'])
    torch.testing.assert_close(plane_swin.stages[0].blocks[0].ffn.layers[1]
                               .weight,
                               official['layers.0.blocks.0.mlp.fc2.weight'])
    assert any('patch_embed.projection.weight (file (8, 3, 4, 4), module '
               '(8, 5, 2, 2))' in m for m in log_lines)
    assert any('converted the official Swin keys' in m for m in log_lines)


def test_torchvision_name_resolves_through_the_hub_cache(tmp_path,
                                                         monkeypatch):
    """torchvision://resnet18 needs no torchvision: it is the file
    resnet18-f37072fd.pth in torch's hub cache (a file put there by hand is
    used as is); a failed download names the URL and where to put the
    file; an unknown name lists the known ones."""
    monkeypatch.setattr(torch.hub, 'get_dir', lambda: str(tmp_path))
    cached = tmp_path / 'checkpoints' / 'resnet18-f37072fd.pth'
    cached.parent.mkdir()
    net = _resnet()
    _torchvision_file(net, cached)
    assert resolve_checkpoint('torchvision://resnet18') == str(cached)
    load_pretrained(net, 'img', _entry(checkpoint='torchvision://resnet18',
                                       ignore=[r'^fc\.']))

    def offline(url, dst, hash_prefix=None, progress=True):
        raise OSError('no network')

    monkeypatch.setattr(torch.hub, 'download_url_to_file', offline)
    with pytest.raises(RuntimeError, match=r'resnet50-0676ba61\.pth\): no '
                       r'network\. Download it elsewhere and copy it to '
                       r'.*checkpoints/resnet50-0676ba61\.pth'):
        resolve_checkpoint('torchvision://resnet50')
    with pytest.raises(ValueError, match="known: \\['resnet18'"):
        resolve_checkpoint('torchvision://vgg16')


def test_unsafe_checkpoint_is_refused(tmp_path):
    """Pretrained files go through the restricted unpickler: a file that
    pickles a function is refused by name, nothing from it runs."""
    torch.save(dict(state_dict={}, hook=print), tmp_path / 'evil.pth')
    with pytest.raises(UnsafeCheckpointError,
                       match=r'Refusing to load checkpoint .*evil\.pth: it '
                       r'pickles builtins\.print'):
        load_pretrained(_resnet(), 'img',
                        _entry(checkpoint=str(tmp_path / 'evil.pth')))


def test_bad_entries_are_named():
    """Each malformed entry names itself and the bad key."""
    with pytest.raises(ValueError, match='pretrained.a must be a dict with'):
        check_entries(dict(a=dict(checkpoint='x')))
    with pytest.raises(ValueError, match=r"pretrained.a: unknown keys "
                       r"\['strict'\]"):
        check_entries(dict(a=dict(module='m', strict=True)))
    with pytest.raises(ValueError, match='style must be one of'):
        check_entries(dict(a=dict(module='m', style='tf')))
    with pytest.raises(ValueError, match='list of patterns'):
        check_entries(dict(a=dict(module='m', ignore='fc')))
    with pytest.raises(ValueError, match='tolerance'):
        check_entries(dict(a=dict(module='m', tolerance=-1)))
    assert check_entries(None) == {}


def test_key_map_renames_the_files_keys(tmp_path):
    """A file whose ResNet stages are called ``block{N}`` (another
    codebase's names) loads with ``key_map`` renaming them to mmdet's
    ``layer{N}``; renaming two keys alike is refused, naming the key; a
    malformed map and a dropped (None) entry are handled at the check."""
    model = _resnet()
    state = _torchvision_file(model, tmp_path / 'plain.pth')
    renamed = {k.replace('layer', 'block', 1): v for k, v in state.items()}
    torch.save(renamed, tmp_path / 'other.pth')
    report = load_pretrained(
        model, 'img', _entry(checkpoint=str(tmp_path / 'other.pth'),
                             key_map=[(r'^block(\d)', r'layer\1')],
                             ignore=[r'^fc\.']))
    assert report['loaded'] == len(state) - 2
    loaded = model.state_dict()
    assert all(torch.equal(loaded[k], v) for k, v in state.items()
               if not k.startswith('fc.'))
    with pytest.raises(PretrainedMismatchError, match='two of the file'):
        load_pretrained(
            _resnet(), 'img', _entry(checkpoint=str(tmp_path / 'other.pth'),
                                     key_map=[(r'^block\d', 'layer1')]))
    with pytest.raises(ValueError, match='key_map must be a list of'):
        check_entries(dict(a=dict(module='m', key_map=['layer'])))
    assert check_entries(dict(a=None, b=dict(module='m'))).keys() == {'b'}
