"""SDG-KL's student as one ONNX graph, checked on samples it was not
exported with (issue 50).

The tiny SDG-KL is traced with synthetic sample 0 and run by onnxruntime
on synthetic samples of other rigs and point counts, on an empty cloud
and on the real nuScenes key frame of ``../shared``; PyTorch's reference
is the model's own ``_forward`` on its default (CPU) code path. The
weights are the freshly built model's: what is checked is that the graph
computes what the model computes, whatever it has learnt.
"""
import contextlib
import io
import json
import os.path as osp

import pytest
import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope

import projects.sdg_occ  # noqa: F401  (registers)
from projects.occ_common.analysis.real_sample import (INFO_FILE,
                                                      MISSING_REASON,
                                                      real_sample_dir)
from projects.occ_common.deployment import (config_time_dim, graph_summary,
                                            info_file_sample, logits_parity,
                                            onnx_session, reference_logits,
                                            run_graph, synthetic_sample)
from projects.occ_common.testing.tool_logs import REPO_ROOT, load_tool
from projects.sdg_occ.deployment import sdg_graph_spec

CONFIG = osp.join(REPO_ROOT, 'configs', 'sdg_occ',
                  'sdgocc-kl_tiny_1xb1-6e_occ3d-nus-synthetic.py')
#: Issue 50's parity criteria (fp32).
ATOL, MIN_AGREEMENT = 1e-3, 0.999


@pytest.fixture(scope='module')
def exported(tmp_path_factory):
    """tools/deployment/export_onnx.py on the tiny SDG-KL (with the camera
    BEV as a third output), verified on synthetic sample 3 (800 points);
    the same model (the tool seeds it alike), its graph spec and an
    onnxruntime session of the graph."""
    out = str(tmp_path_factory.mktemp('onnx') / 'kl.onnx')
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        report = load_tool('tools/deployment/export_onnx.py').main([
            CONFIG, 'none', '--out', out, '--bev-output', '--verify',
            'synthetic:3:800'
        ])
    cfg = Config.fromfile(CONFIG)
    init_default_scope('mmdet3d')
    torch.manual_seed(0)
    model = MODELS.build(cfg.model).eval()
    spec = sdg_graph_spec(model, config_time_dim(cfg), with_bev=True)
    return dict(cfg=cfg, model=model, spec=spec, path=out, report=report,
                printed=printed.getvalue(), session=onnx_session(out))


def _check(exported, batch):
    """Run the graph on ``batch``; assert parity with PyTorch, of the
    logits and of the camera BEV before the head (a random head could
    hide a wrong BEV)."""
    model, spec = exported['model'], exported['spec']
    out = run_graph(exported['session'], spec.feeds(batch))
    seen = []
    hook = model.camera_bev_conv.register_forward_hook(
        lambda module, args, result: seen.append(result))
    try:
        reference = reference_logits(model, batch)
    finally:
        hook.remove()
    parity = logits_parity(reference, out['occ_logits'])
    assert parity['max_abs_diff'] <= ATOL, parity
    assert parity['argmax_agreement'] >= MIN_AGREEMENT, parity
    torch.testing.assert_close(
        torch.from_numpy(out['camera_bev']), seen[0], atol=1e-4, rtol=1e-4)
    return out, parity


@pytest.fixture(scope='module')
def seed1(exported):
    """Synthetic sample 1 (1,500 points, another rig) and the graph's
    outputs on it, checked."""
    batch = synthetic_sample(exported['cfg'], 1, 1500)
    return batch, _check(exported, batch)[0]


def test_graph_has_the_sample_as_inputs(exported):
    """Every input is read by the graph (none was traced as a constant),
    the point count is symbolic, and no operator has a data-dependent
    output shape (NonZero, Unique, sorts) or an inverse."""
    summary = graph_summary(exported['path'])
    assert list(summary['inputs']) == [
        'imgs', 'points', 'cam2img', 'lidar2cam', 'img_aug_matrix',
        'lidar2img'
    ]
    assert summary['inputs']['points'] == ['num_points', 5]
    assert summary['inputs']['imgs'] == [1, 6, 3, 128, 352]
    assert summary['outputs']['occ_logits'] == [1, 18, 200, 200, 16]
    assert summary['unused_inputs'] == []
    assert not {'NonZero', 'Unique', 'TopK', 'Inverse'} & set(summary['ops'])
    assert 'Constant' not in summary['ops']  # moved to initializers
    assert summary['ops']['ScatterElements'] == 3  # depth map, two pools


def test_parity_on_other_rigs_and_point_counts(exported, seed1):
    """Synthetic samples with another camera rig (yaw, pitch, focal,
    principal point, a resize / shift / rotation / flip augmentation) and
    another point count (1,500 and 3,100) than the traced sample (1,000
    points); ``seed1`` checked the first."""
    assert seed1[1]['occ_labels'].shape == (1, 200, 200, 16)
    _check(exported, synthetic_sample(exported['cfg'], 2, 3100))


def test_the_points_guide_the_graph(exported, seed1):
    """Sample 1's images and rig without points: the graph's camera BEV
    changes (the LiDAR guidance is an input, not a constant) and still
    matches PyTorch, whose SDG lift then falls back to LSS everywhere."""
    batch, with_points = seed1
    batch = dict(batch, inputs=dict(
        batch['inputs'], points=[batch['inputs']['points'][0][:0]]))
    without, _ = _check(exported, batch)
    assert (with_points['camera_bev'] != without['camera_bev']).any()


@pytest.mark.skipif(real_sample_dir() is None, reason=MISSING_REASON)
def test_parity_on_the_real_sample(exported, tmp_path):
    """The real nuScenes key frame through the config's test pipeline:
    six real cameras resized to 128 x 352 (a non-identity augmentation),
    the LiDAR at yaw -90 deg, ~24k points."""
    batch = info_file_sample(exported['cfg'],
                             osp.join(real_sample_dir(), INFO_FILE),
                             str(tmp_path))
    _, parity = _check(exported, batch)
    assert batch['inputs']['points'][0].shape[0] > 20000


def test_tool_writes_the_graph_its_json_and_the_parity(exported):
    """One printed line per step; FILE.json holds the report: the inputs,
    nothing outside the graph, the verified sample."""
    out, report = exported['path'], exported['report']
    assert f'exported {out}: ' in exported['printed']
    assert 'verify synthetic:3:800: 800 points, max |diff| ' in \
        exported['printed']
    with open(osp.splitext(out)[0] + '.json') as file:
        info = json.load(file)
    assert info == json.loads(json.dumps(report))
    assert list(info['graphs']) == ['prediction']
    graph = info['graphs']['prediction']
    assert graph['verify']['synthetic:3:800']['passed']
    assert graph['outside_graph'] == 'nothing'
    assert graph['inputs']['points']['shape'] == ['num_points', 5]
    assert info['exported_with'] == 'synthetic:0 (1000 points)'


def test_tool_refuses_a_temporal_config(tmp_path):
    """Two-frame SDG-Fusion reads cached BEVs of earlier frames: refused
    in one line, nothing written."""
    config = osp.join(REPO_ROOT, 'configs', 'sdg_occ',
                      'sdgocc-fusion-2f_tiny_1xb1-6e_occ3d-nus-synthetic.py')
    with pytest.raises(SystemExit) as exc:
        load_tool('tools/deployment/export_onnx.py').main(
            [config, 'none', '--out', str(tmp_path / 'x.onnx')])
    assert 'num_frames=2' in str(exc.value.code)
    assert not osp.exists(tmp_path / 'x.onnx')
