"""The paper configs initialise as the Runner does (``init_weights``),
without torchvision and without a download (issue 15 item 2, issue 11
item 7).

Their ResNet-50 starts from ``torchvision://resnet50``: here that name
resolves to a file the test writes into a temporary hub cache (ImageNet
layout: the backbone's keys plus the classifier ``fc``), so every paper
model is checked to load it, and what it must refuse is checked too.
"""
import logging
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.logging import MMLogger
from mmengine.registry import init_default_scope

from projects.occ_common.models.pretrained import PretrainedMismatchError
from projects.occ_common.testing.imagenet_swin import (constant_like,
                                                       official_swin_state)

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
OCC_CYL = 'configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py'
PAPER_CONFIGS = [
    OCC_CYL,
    'configs/occ_cyl/occcyl_r50-swins_3xb1-24e_occ3d-nus.py',
    'configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py',
    'configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_surroundocc-nus.py',
    'configs/sdg_occ/sdgocc-kl_r50_4xb2-24e_occ3d-nus.py',
    'configs/sdg_occ/sdgocc-kl_r50_4xb2-24e_surroundocc-nus.py',
]


@pytest.fixture(autouse=True)
def quiet_init_log():
    """mmengine logs every parameter's initialisation at INFO (1.5 k lines
    per paper model); keep warnings and errors only."""
    logger = MMLogger.get_current_instance()
    level = logger.level
    logger.setLevel(logging.WARNING)
    yield
    logger.setLevel(level)


def _build(path, **options):
    cfg = Config.fromfile(osp.join(ROOT, path))
    cfg.merge_from_dict({f'model.{k}': v for k, v in options.items()})
    init_default_scope(cfg.default_scope)
    torch.manual_seed(0)
    return MODELS.build(cfg.model)


def _r50_state():
    """A ResNet-50 in torchvision's layout: mmdet's keys (the same names),
    no BN counters, plus the ImageNet classifier; values that no
    initialisation produces (0.01 * (1 + index of the tensor))."""
    init_default_scope('mmdet3d')
    r50 = MODELS.build(dict(type='mmdet.ResNet', depth=50, init_cfg=None))
    state = {
        k: torch.full_like(v, 0.01 * (i + 1))
        for i, (k, v) in enumerate(r50.state_dict().items())
        if not k.endswith('num_batches_tracked')
    }
    state['fc.weight'] = torch.zeros(1000, 2048)
    state['fc.bias'] = torch.zeros(1000)
    return state


#: The official ImageNet Swins the OccCylindrical configs start from: file
#: name -> (depths, heads); 96 wide, window 7, 4 x 4 RGB patches.
IMAGENET_SWINS = {
    'swin_small_patch4_window7_224.pth': ((2, 2, 18, 2), (3, 6, 12, 24)),
    'swin_tiny_patch4_window7_224.pth': ((2, 2, 6, 2), (3, 6, 12, 24)),
}


def _write_imagenet_swin(path, depths, heads):
    """The official file's keys and shapes, each a constant (stride-0
    tensors: a few kB for Swin-S's 49.6 M values)."""
    init_default_scope('mmdet3d')
    swin = MODELS.build(
        dict(type='mmdet.SwinTransformer', embed_dims=96, depths=depths,
             num_heads=heads, window_size=7, init_cfg=None))
    state = official_swin_state(swin, value=constant_like(0.02))
    torch.save(dict(model=state), path)


@pytest.fixture(scope='module')
def hub(tmp_path_factory):
    """torch's hub cache holding torchvision://resnet50's file and the
    ImageNet Swin-S and Swin-T files."""
    root = tmp_path_factory.mktemp('hub')
    (root / 'checkpoints').mkdir()
    state = _r50_state()
    torch.save(state, root / 'checkpoints' / 'resnet50-0676ba61.pth')
    for name, (depths, heads) in IMAGENET_SWINS.items():
        _write_imagenet_swin(root / 'checkpoints' / name, depths, heads)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(torch.hub, 'get_dir', lambda: str(root))
        yield root, state


def _img_backbone(model):
    return model.pretrained['img_backbone']['module'], model.get_submodule(
        model.pretrained['img_backbone']['module'])


@pytest.mark.parametrize('path', PAPER_CONFIGS,
                         ids=lambda p: osp.basename(p)[:-3])
def test_paper_config_init_weights_loads_imagenet_r50(path, hub):
    """init_weights loads all 265 ResNet-50 tensors (53 convs, 53 BN x 4;
    the fc classifier is ignored and reported) and the model initialises
    without torchvision.
    OccCylindrical keeps stage 1 frozen, BN in eval mode and (as OCCFusion)
    every BN's affine parameters frozen, as configured for fine-tuning:
    trainable are the convs of stages 2-4 (their shortcut convs and the
    DCN offsets included); SDG-OCC trains its whole backbone."""
    _, state = hub
    model = _build(path)
    model.init_weights()
    name, backbone = _img_backbone(model)
    loaded = backbone.state_dict()
    assert all(
        torch.equal(loaded[k], v) for k, v in state.items()
        if not k.startswith('fc.'))
    assert len(state) - 2 == 265
    frozen = [n for n, p in backbone.named_parameters() if not p.requires_grad]
    if 'occcyl' in path:
        trainable = [n for n, p in backbone.named_parameters()
                     if p.requires_grad]
        assert trainable and all(
            n.startswith(('layer2', 'layer3', 'layer4'))
            and ('.conv' in n or '.downsample.0.' in n) for n in trainable)
        assert all(n.startswith(('conv1', 'bn1', 'layer1')) or '.bn' in n
                   or '.downsample.1.' in n for n in frozen)
        model.train()
        assert not backbone.bn1.training
        assert not backbone.layer4[0].bn1.training
    else:
        assert frozen == []


@pytest.mark.parametrize('path', [
    OCC_CYL,
    'configs/occ_cyl/occcyl-lite_r50-swint_3xb1-24e_surroundocc-nus.py'
], ids=['swin-s', 'swin-t'])
def test_occcyl_configs_load_imagenet_swin_and_keep_dcn_offsets(path, hub):
    """Issue 47: the TPV encoder starts from the official ImageNet Swin-S
    (Swin-T for the lite model): every block loads (the file's 0.02), the
    2 x 2, 128-channel patch embedding keeps its initialisation. The DCNv2
    offset convs of ResNet stages 3-4, absent from torchvision's file, stay
    at mmcv's zeros while conv2's own weight loads."""
    model = _build(path)
    model.init_weights()
    swin = model.tpv_encoder.backbone
    deepest = swin.stages[2].blocks[-1]
    assert bool((deepest.attn.w_msa.qkv.weight == 0.02).all())
    assert bool((swin.stages[0].blocks[0].ffn.layers[1].weight == 0.02).all())
    assert not bool((swin.patch_embed.projection.weight == 0.02).all())
    _, state = hub
    block = model.img_encoder.backbone.layer3[0]
    assert type(block.conv2).__name__ == 'Float32DCNv2'
    assert torch.equal(block.conv2.weight, state['layer3.0.conv2.weight'])
    assert not block.conv2.conv_offset.weight.any()
    assert not block.conv2.conv_offset.bias.any()


def test_without_checkpoint_the_backbone_trains_normally():
    """checkpoint=None with frozen_stages=-1 and live BN (statistics and
    affine parameters): init_weights passes, every backbone parameter
    trains and model.train() puts every BN in training mode (it updates
    its statistics)."""
    model = _build(
        OCC_CYL, **{
            'pretrained.img_backbone.checkpoint': None,
            'img_encoder.backbone.frozen_stages': -1,
            'img_encoder.backbone.norm_eval': False,
            'img_encoder.backbone.norm_cfg.requires_grad': True
        })
    model.init_weights()
    model.train()
    backbone = model.img_encoder.backbone
    assert all(p.requires_grad for p in backbone.parameters())
    norms = [m for m in backbone.modules()
             if isinstance(m, torch.nn.BatchNorm2d)]
    assert len(norms) == 53 and all(m.training for m in norms)


def test_without_checkpoint_frozen_random_layers_are_refused():
    """The old paper config: no weights but frozen_stages=1 and
    norm_eval=True, i.e. a random stem frozen forever and BN statistics
    that never update. init_weights refuses it and says what to change."""
    model = _build(OCC_CYL, **{'pretrained.img_backbone.checkpoint': None})
    with pytest.raises(ValueError,
                       match=r'pretrained.img_backbone: no checkpoint, but '
                       r'RecomputedResNet has frozen_stages=1, '
                       r'norm_eval=True'):
        model.init_weights()


def test_without_checkpoint_frozen_bn_affine_is_refused():
    """The paper config's BN affine parameters frozen (as OCCFusion, for
    fine-tuning) without a checkpoint: the stages and statistics train,
    but the 106 BN weights and biases (53 BN x 2) would stay 1 and 0
    forever. init_weights refuses it, naming the count and the first."""
    model = _build(
        OCC_CYL, **{
            'pretrained.img_backbone.checkpoint': None,
            'img_encoder.backbone.frozen_stages': -1,
            'img_encoder.backbone.norm_eval': False
        })
    with pytest.raises(ValueError,
                       match=r'pretrained.img_backbone: no checkpoint, but '
                       r'106 parameters of RecomputedResNet do not train '
                       r'\(first: bn1.weight'):
        model.init_weights()


def test_fcos3d_r101_dcn_checkpoint_is_refused_by_name(tmp_path, hub):
    """FCOS3D's public weights (caffe-style ResNet-101 with DCN in stages 3
    and 4, in a detector checkpoint) into the ResNet-50, which has DCN in
    the same stages (issue 47): the 17 layer3 blocks it lacks bring 15
    tensors each (the BN counters aside) and their DCN offset convs 2
    more, 17 * (15 + 2) = 289 unexpected keys (307 into the ResNet-50
    without DCN of before, 358 with the counters as mmengine reports). The
    load is refused naming the file, the part and layer3.6's keys; nothing
    is loaded (conv1 is not the file's 0.01)."""
    _, state = hub
    r101 = {k: v for k, v in state.items() if not k.startswith('fc.')}
    block = {k[len('layer3.5.'):]: v for k, v in state.items()
             if k.startswith('layer3.5.')}
    for i in range(6, 23):
        r101.update({f'layer3.{i}.{k}': v for k, v in block.items()})
    for stage, blocks, width in (('layer3', 23, 256), ('layer4', 3, 512)):
        for i in range(blocks):
            r101[f'{stage}.{i}.conv2.conv_offset.weight'] = torch.zeros(
                27, width, 3, 3)
            r101[f'{stage}.{i}.conv2.conv_offset.bias'] = torch.zeros(27)
    path = tmp_path / 'fcos3d_r101_dcn.pth'
    torch.save(dict(state_dict={f'backbone.{k}': v
                                for k, v in r101.items()}), path)
    model = _build(
        OCC_CYL, **{
            'pretrained.img_backbone.checkpoint': str(path),
            'pretrained.img_backbone.prefix': 'backbone.'
        })
    with pytest.raises(PretrainedMismatchError) as err:
        model.init_weights()
    message = str(err.value)
    assert f'checkpoint {path} does not fit img_encoder.backbone' in message
    assert '289 unexpected, 0 missing and 0 mis-shaped keys' in message
    assert "'layer3.6.conv1.weight'" in message
    conv1 = model.img_encoder.backbone.conv1.weight
    assert not torch.equal(conv1, torch.full_like(conv1, 0.01))


def test_entry_naming_a_missing_module_is_refused():
    """A pretrained entry whose module path the model lacks is named."""
    model = _build(OCC_CYL, **{
        'pretrained.img_backbone.module': 'img_backbone',
    })
    with pytest.raises(ValueError, match="pretrained.img_backbone names "
                       "module 'img_backbone'"):
        model.init_weights()
