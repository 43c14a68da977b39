"""The release's camera start: a BEVDet checkpoint through the checked
``pretrained`` loader (``bevdet_pretrained`` of the SDG-OCC model base).

The file is hand-made in BEVDet-R50-CBGS's layout (the release's
``load_from``): ``img_backbone.*`` and ``img_neck.*`` as this library
names them, the BEV encoder's residual blocks as BEVDet's CustomResNet
names them (``img_bev_encoder_backbone.layers.{stage}.{block}.conv1`` ...,
a 3x3 ``downsample`` conv with bias where this encoder has a 1x1 conv + BN
``shortcut``), plus what no entry loads (the depth net, FPN-LSS, the
detection head). Every tensor is a distinct constant (stride 0: a few kB).
"""
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

import projects.sdg_occ  # noqa: F401  (registers)
from projects.occ_common.models.pretrained import PretrainedMismatchError
from projects.occ_common.testing.tool_logs import REPO_ROOT, quiet_logger

CONFIG = osp.join(REPO_ROOT, 'configs', 'sdg_occ',
                  'sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py')


def _constant(shape, value):
    return torch.tensor(float(value)).expand(shape)


def _bevdet_file(model, path):
    """Key -> (shape, value) of the hand-made file, written to ``path``."""
    state = {}

    def put(key, shape):
        state[key] = _constant(shape, 0.001 * (len(state) + 1))

    for part in ('img_backbone', 'img_neck'):
        for key, value in getattr(model, part).state_dict().items():
            if not key.endswith('num_batches_tracked'):
                put(f'{part}.{key}', value.shape)
    for key, value in model.bev_encoder.state_dict().items():
        if key.startswith('stages.') and '.shortcut.' not in key and \
                not key.endswith('num_batches_tracked'):
            put('img_bev_encoder_backbone.layers.' + key[len('stages.'):],
                value.shape)
    for stage, (c_in, c_out) in enumerate([(64, 128), (128, 256),
                                           (256, 512)]):
        prefix = f'img_bev_encoder_backbone.layers.{stage}.0.downsample'
        put(f'{prefix}.weight', (c_out, c_in, 3, 3))
        put(f'{prefix}.bias', (c_out, ))
    put('img_bev_encoder_neck.conv.0.weight', (512, 640, 3, 3))
    put('img_view_transformer.depth_net.weight', (123, 256, 1, 1))
    put('pts_bbox_head.shared_conv.conv.weight', (64, 256, 3, 3))
    torch.save(dict(state_dict=state, meta=dict()), path)
    return state


@pytest.fixture(scope='module')
def started(tmp_path_factory):
    """The paper SDG-Fusion model initialised from the hand-made file."""
    cfg = Config.fromfile(CONFIG)
    init_default_scope('mmdet3d')
    path = str(tmp_path_factory.mktemp('bevdet') / 'bevdet-r50-cbgs.pth')
    entries = {
        name: dict(entry, checkpoint=path)
        for name, entry in cfg.bevdet_pretrained.items()
    }
    cfg.merge_from_dict({'model.pretrained': entries})
    torch.manual_seed(0)
    model = MODELS.build(cfg.model)
    state = _bevdet_file(model, path)
    with quiet_logger():
        model.init_weights()
    return model, state, cfg, path


def test_resnet_and_fpn_load_whole(started):
    """All 265 ResNet-50 tensors and the FPN's 6 (two lateral convs, one
    output conv, weight and bias each) equal the file's constants."""
    model, state, _, _ = started
    for part, count in (('img_backbone', 265), ('img_neck', 6)):
        loaded = {
            k: v for k, v in getattr(model, part).state_dict().items()
            if not k.endswith('num_batches_tracked')
        }
        assert len(loaded) == count
        for key, value in loaded.items():
            assert torch.equal(value, state[f'{part}.{key}']), key


def test_bev_encoder_residual_blocks_load_renamed(started):
    """``layers.{s}.{b}.*`` load into ``stages.{s}.{b}.*`` (3 stages x 2
    blocks x 2 convs and 2 BNs = 60 tensors); the 1x1 + BN shortcuts, the
    top-down merges and the output conv keep their initialisation (no
    tensor of theirs is a file constant)."""
    model, state, _, _ = started
    constants = {float(v.flatten()[0]) for v in state.values()}
    loaded = 0
    for key, value in model.bev_encoder.state_dict().items():
        if key.endswith('num_batches_tracked'):
            continue
        theirs = 'img_bev_encoder_backbone.layers.' + key[len('stages.'):]
        if theirs in state:
            assert torch.equal(value, state[theirs]), key
            loaded += 1
        elif value.numel() > 1:
            assert not (value == value.flatten()[0]).all() or \
                float(value.flatten()[0]) not in constants, key
    assert loaded == 60


def test_without_the_key_map_the_file_is_refused(started):
    """The same file without the renaming: the residual blocks are
    unexpected keys and the loader refuses it, naming the entry."""
    _, _, cfg, path = started
    entries = {
        name: dict(entry, checkpoint=path)
        for name, entry in cfg.bevdet_pretrained.items()
    }
    entries['bev_encoder']['key_map'] = []
    cfg.merge_from_dict({'model.pretrained': entries})
    cfg.model.pretrained.bev_encoder.key_map = []
    model = MODELS.build(cfg.model)
    with pytest.raises(PretrainedMismatchError,
                       match=r'pretrained\.bev_encoder: .* unexpected'):
        model.init_weights()
