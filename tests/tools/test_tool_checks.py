"""tools/train.py and tools/test.py refuse bad options, configs and
checkpoints with a clear error before doing any work.

The tools run in this process (``main(argv)``) on the toy config, which
trains and evaluates in seconds.
"""
import importlib
import os
import os.path as osp
import re
import uuid

import pytest
import torch

from projects.occ_common.fileio import (CorruptFileError,
                                        UnsafeCheckpointError,
                                        load_checkpoint_file)
from projects.occ_common.testing.tool_logs import load_tool, run_tool

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'tests', 'data', 'configs', 'toy_occ.py')


config_checks = importlib.import_module(
    'projects.occ_common.engine.config_checks')
test_tool, train_tool = load_tool('tools/test.py'), load_tool('tools/train.py')


def _name():
    return f'experiment_name=tool_checks_{uuid.uuid4().hex}'


@pytest.mark.parametrize('item, msg', [
    ('train_cfg.max_epochs', "expected KEY=VALUE, got 'train_cfg.max_epochs'"),
    ('=3', "expected KEY=VALUE, got '=3'"),
    ('model.in_channels=[1,2', "cannot parse the value of "
     "'model.in_channels=[1,2' (Imbalanced brackets"),
])
def test_malformed_cfg_options_name_the_item(item, msg, capsys):
    """mmengine's DictAction failed with 'not enough values to unpack'."""
    for tool in (train_tool, test_tool):
        argv = [CONFIG] + (['x.pth'] if tool is test_tool else [])
        with pytest.raises(SystemExit) as err:
            tool.parse_args(argv + ['--cfg-options', item])
        assert err.value.code == 2
        assert f'--cfg-options: {msg}' in capsys.readouterr().err


@pytest.mark.parametrize('item, msg', [
    ('train_cfg.max_epochs=two', "train_cfg.max_epochs='two' \\(a string\\)"
     ', but the config has the integer 2 there'),
    ('train_cfg.max_epochs=2.5', 'max_epochs=.2.5. \\(a number\\)'),
    ('train_dataloader.num_workers=true', 'num_workers=.true. \\(a bool\\)'),
    ('model.in_channels=[3,3]', 'in_channels=.\\[3,3\\]. \\(a list\\)'),
])
def test_wrongly_typed_cfg_options_name_key_and_kind(item, msg):
    """They used to fail deep in the training loop, or not at all."""
    args = train_tool.parse_args([CONFIG, '--cfg-options', item])
    with pytest.raises(ValueError, match=msg):
        train_tool.build_cfg(args)


#: The toy config's values: train_cfg.max_epochs = 2, batch_size = 2, one
#: MultiStepLR in param_scheduler, model a dict of three keys (its repr is
#: longer than config_checks.MAX_QUOTED, so only its kind is named).
WRONG_KINDS = [
    ('train_cfg.max_epochs=abc', "train_cfg.max_epochs='abc' (a string), "
     'but the config has the integer 2 there'),
    ('train_dataloader.batch_size=[1,2]', "train_dataloader.batch_size="
     "'[1,2]' (a list), but the config has the integer 2 there"),
    ('model=abc', "model='abc' (a string), but the config has a dict "
     'there'),
    ('train_cfg.max_epochs.x=1', "train_cfg.max_epochs.x='1', but the "
     'config has the integer 2 at train_cfg.max_epochs, not a dict to set '
     'a key in'),
    ('param_scheduler.3.gamma=0.1', "param_scheduler.3.gamma='0.1', but "
     "param_scheduler is a list of 1 item, which has no item '3'"),
]


@pytest.mark.parametrize('item, shown', WRONG_KINDS)
def test_wrong_kind_ends_train_and_test_with_one_line(item, shown, capsys):
    """Status 2 and one line 'PROG: error: ...' naming key, given value and
    the kind it replaces, as argparse ends on a malformed item. Before:
    a ValueError traceback (the first two), a TypeError / IndexError
    traceback from mmengine's merge (the last two), or a traceback when
    the Runner built the model from the string 'abc'."""
    for tool in (train_tool, test_tool):
        argv = [CONFIG] + (['x.pth'] if tool is test_tool else [])
        with pytest.raises(SystemExit) as err:
            tool.main(argv + ['--cfg-options', item, _name()])
        assert err.value.code == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 1, lines
        assert re.fullmatch(
            r'\S+: error: --cfg-options of the wrong kind: ' +
            re.escape(shown),
            lines[0]), lines[0]


def test_wrong_kind_from_the_command_line_is_one_line():
    """The script itself: exit status 2, stderr exactly one line naming the
    program, no traceback, no work dir created."""
    proc = run_tool('tools/train.py', CONFIG, '--cfg-options',
                    'train_cfg.max_epochs=abc', timeout=300)
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert proc.stderr == (
        "train.py: error: --cfg-options of the wrong kind: "
        "train_cfg.max_epochs='abc' (a string), but the config has the "
        'integer 2 there\n')


@pytest.mark.parametrize('script', [
    'tools/analysis_tools/benchmark.py',
    'tools/analysis_tools/cylinder_ceiling.py',
])
def test_analysis_tools_end_a_wrong_kind_in_one_line(script, monkeypatch,
                                                     capsys):
    """The analysis tools check and end alike: benchmark.py merges its
    DictAction options through check_cfg_options, cylinder_ceiling.py
    through apply_cfg_options; both exit 2 with one line of stderr (run
    in this process: the check is the tool's logic, not its start-up)."""
    import runpy
    monkeypatch.setattr('sys.argv', [
        osp.join(ROOT, script), CONFIG, '--cfg-options',
        'train_cfg.max_epochs=abc'
    ])
    with pytest.raises(SystemExit) as end:
        runpy.run_path(osp.join(ROOT, script), run_name='__main__')
    assert end.value.code == 2
    stderr = capsys.readouterr().err
    assert len(stderr.splitlines()) == 1, stderr[-3000:]
    name = osp.basename(script)
    assert stderr.startswith(
        f"{name}: error: --cfg-options of the wrong kind: "
        "train_cfg.max_epochs='abc' (a string), but the config has the "
        'integer 2 there'), stderr


def test_wrong_kind_stays_a_value_error_for_callers():
    """build_cfg (and the analysis tools' load_tool_config) still raise:
    CfgOptionsError is a ValueError; only the tools' main turns it into
    the one-line exit."""
    args = test_tool.parse_args([CONFIG, 'x.pth', '--cfg-options', 'model=1'])
    with pytest.raises(config_checks.CfgOptionsError,
                       match="model='1' \\(an integer\\), but the "
                       'config has a dict there'):
        test_tool.build_cfg(args)
    assert issubclass(config_checks.CfgOptionsError, ValueError)


def test_kind_preserving_overrides_pass():
    """An integer for a float, None anywhere, new keys, a number typed for
    a string (taken as the text typed)."""
    args = train_tool.parse_args([
        CONFIG, '--cfg-options', 'optim_wrapper.optimizer.lr=1',
        'load_from=None', 'model.new_key=5', 'default_scope=007',
        'train_dataloader.dataset.num_samples=4'
    ])
    cfg = train_tool.build_cfg(args)
    assert cfg.optim_wrapper.optimizer.lr == 1
    assert cfg.model.new_key == 5
    assert cfg.train_dataloader.dataset.num_samples == 4
    assert cfg.default_scope == '007'


def test_top_level_typo_is_refused(tmp_path):
    """tset_dataloader was silently ignored (the base test_dataloader
    ran); own keys far from every Runner key are fine."""
    config = tmp_path / 'typo.py'
    config.write_text(f"_base_ = ['{CONFIG}']\n"
                      'tset_dataloader = dict(batch_size=1)\n'
                      'my_grid = [8, 8, 4]\n')
    for tool, extra in ((train_tool, []), (test_tool, ['x.pth'])):
        args = tool.parse_args([str(config)] + extra)
        with pytest.raises(ValueError,
                           match="unknown top-level key 'tset_dataloader' "
                           "\\(did you mean 'test_dataloader'\\?\\)"):
            tool.build_cfg(args)
    args = train_tool.parse_args(
        [CONFIG, '--cfg-options', 'val_evaluater.type=X'])
    with pytest.raises(ValueError, match="'val_evaluater' \\(did you mean "
                       "'val_evaluator'"):
        train_tool.build_cfg(args)
    assert config_checks.edit_distance('tset', 'test') == 1
    assert config_checks.edit_distance('train_pipeline',
                                       'tta_pipeline') == 3


@pytest.fixture(scope='module')
def toy_checkpoint(tmp_path_factory):
    """epoch_1.pth of the toy config (tools/train.py in this process)."""
    work_dir = str(tmp_path_factory.mktemp('toy'))
    train_tool.main([
        CONFIG, '--work-dir', work_dir, '--cfg-options',
        'train_cfg.max_epochs=1', _name()
    ])
    return osp.join(work_dir, 'epoch_1.pth')


def _evaluate(checkpoint, tmp_path, *extra):
    test_tool.main([
        CONFIG, checkpoint, '--work-dir',
        str(tmp_path / uuid.uuid4().hex), *extra, '--cfg-options', _name()
    ])


def _modified(toy_checkpoint, tmp_path, edit):
    checkpoint = load_checkpoint_file(toy_checkpoint)
    edit(checkpoint['state_dict'])
    path = str(tmp_path / 'modified.pth')
    torch.save(checkpoint, path)
    return path


def test_checkpoint_of_another_model_is_refused(toy_checkpoint, tmp_path):
    """Renamed keys and another shape: refused (before, rc 0 and a random
    model's metric), unless --allow-key-mismatch."""

    def other_model(state):
        state['head.weight'] = state.pop('classifier.weight')
        state['classifier.bias'] = torch.zeros(5)

    path = _modified(toy_checkpoint, tmp_path, other_model)
    with pytest.raises(ValueError) as err:
        _evaluate(path, tmp_path)
    message = str(err.value)
    assert message.startswith(f'{path} does not fit the model of {CONFIG}')
    assert "1 of the model's 2 tensors are missing (classifier.weight)" in \
        message
    assert "1 keys are not the model's (head.weight)" in message
    assert 'classifier.bias (5,) vs (3,)' in message
    assert '--allow-key-mismatch' in message
    _evaluate(_modified(toy_checkpoint, tmp_path,
                        lambda s: s.pop('classifier.bias')), tmp_path,
              '--allow-key-mismatch')


def _load_with_benchmark(path):
    tool = load_tool('tools/analysis_tools/benchmark.py')
    return tool.Subject(CONFIG, path,
                        tool.parse_args([CONFIG, '--device', 'cpu']))


def _load_with_exporter(path):
    from mmengine.config import Config
    return load_tool('tools/deployment/export_onnx.py').load_model(
        Config.fromfile(CONFIG), path)


def _load_with_init_model(path):
    from projects.occ_common.apis import init_model
    return init_model(CONFIG, path)


@pytest.mark.parametrize(
    'load', [_load_with_benchmark, _load_with_exporter,
             _load_with_init_model],
    ids=['benchmark', 'export_onnx', 'init_model'])
def test_every_loader_refuses_another_model(load, toy_checkpoint, tmp_path):
    """The tools that load a trained model themselves go through one
    checked path (``projects.occ_common.apis.init_model``, which the demo,
    visualize_occ.py and depth_accuracy.py call too): a checkpoint with a
    renamed key is refused naming the file. Before, benchmark.py timed it
    with the renamed tensor left random, exit 0."""

    def renamed(state):
        state['head.weight'] = state.pop('classifier.weight')

    path = _modified(toy_checkpoint, tmp_path, renamed)
    with pytest.raises(ValueError, match=re.escape(
            f'{path} does not fit the model of {CONFIG}')):
        load(path)
    model = load(toy_checkpoint)
    model = getattr(model, 'model', model)
    state = load_checkpoint_file(toy_checkpoint)['state_dict']
    assert torch.equal(model.state_dict()['classifier.weight'],
                       state['classifier.weight'])


def test_nan_weights_are_refused_even_when_allowed(toy_checkpoint,
                                                   tmp_path):
    """An all-NaN checkpoint evaluated with rc 0 before."""
    path = _modified(toy_checkpoint, tmp_path,
                     lambda s: s['classifier.weight'].fill_(float('nan')))
    for extra in ([], ['--allow-key-mismatch']):
        with pytest.raises(ValueError,
                           match='holds non-finite weights: classifier.'
                           'weight \\(9 of 9 values\\)'):
            _evaluate(path, tmp_path, *extra)


class _Evil:

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f'touch {self.marker}', ))


@pytest.mark.parametrize('damage', ['truncated', 'empty', 'malicious'])
def test_bad_checkpoint_files_through_test_and_resume(
        damage, toy_checkpoint, tmp_path):
    """tools/test.py CKPT and tools/train.py --resume CKPT name the file;
    a payload never runs (a truncated checkpoint used to fail with
    'PytorchStreamReader failed reading zip archive')."""
    path = str(tmp_path / 'bad.pth')
    marker = tmp_path / 'pwned'
    if damage == 'malicious':
        torch.save({'state_dict': {}, 'meta': _Evil(marker)}, path)
        error = UnsafeCheckpointError
    else:
        with open(toy_checkpoint, 'rb') as f:
            data = f.read()
        with open(path, 'wb') as f:
            f.write(data[:len(data) // 2] if damage == 'truncated' else b'')
        error = CorruptFileError
    with pytest.raises(error, match=path):
        _evaluate(path, tmp_path)
    with pytest.raises(error, match=path):
        train_tool.main([
            CONFIG, '--work-dir',
            str(tmp_path / 'resume'), '--resume', path, '--cfg-options',
            _name()
        ])
    assert not marker.exists()


def _other_model(state):
    """The toy model's checkpoint with its classifier renamed and resized,
    as another model's would be."""
    state['head.weight'] = state.pop('classifier.weight')
    state['classifier.bias'] = torch.zeros(5)


def _train(tmp_path, *extra, options=()):
    train_tool.main([
        CONFIG, '--work-dir',
        str(tmp_path / uuid.uuid4().hex), *extra, '--cfg-options',
        'train_cfg.max_epochs=1', 'train_cfg.val_interval=100', _name(),
        *options
    ])


def test_load_from_another_model_is_refused(toy_checkpoint, tmp_path):
    """load_from= the other model's checkpoint: refused, naming the file
    and the first mismatched keys (before: it trained from random weights
    with two warning lines), unless --allow-key-mismatch (fine-tuning a
    model whose head differs)."""
    path = _modified(toy_checkpoint, tmp_path, _other_model)
    with pytest.raises(ValueError) as err:
        _train(tmp_path, options=[f'load_from={path}'])
    message = str(err.value)
    assert message.startswith(f'{path} does not fit the model of {CONFIG}')
    assert "tensors are missing (classifier.weight)" in message
    assert 'Training from it would start' in message
    assert '--allow-key-mismatch to tools/train.py' in message
    _train(tmp_path, '--allow-key-mismatch',
           options=[f'load_from={_modified(toy_checkpoint, tmp_path, dict)}'])


def test_resume_with_another_model_names_the_file(toy_checkpoint,
                                                  tmp_path):
    """--resume with the other model's checkpoint: refused before its
    weights are loaded, naming the file, --allow-key-mismatch or not.
    Before, mmengine loaded the weights that fit and logged the others;
    here (the optimizer state still fits the toy's two parameters) the run
    then went on, and between the two paper models the optimizer failed
    without naming the file."""
    path = _modified(toy_checkpoint, tmp_path, _other_model)
    for extra in ([], ['--allow-key-mismatch']):
        with pytest.raises(ValueError,
                           match=f'--resume: {re.escape(path)} does not fit'
                           '.* resumes only from a checkpoint of its own'):
            _train(tmp_path, '--resume', path, *extra)


def test_env_cfg_typo_is_refused():
    """env_cfg.cudnn_benchmak (and an mp_cfg typo) were silently
    ignored by mmengine's Runner.setup_env."""
    args = train_tool.parse_args(
        [CONFIG, '--cfg-options', 'env_cfg.cudnn_benchmak=True'])
    with pytest.raises(ValueError,
                       match=r"unknown key in env_cfg: 'cudnn_benchmak' "
                       r"\(did you mean 'cudnn_benchmark'\?\)"):
        train_tool.build_cfg(args)
    args = test_tool.parse_args(
        [CONFIG, 'x.pth', '--cfg-options', 'env_cfg.mp_cfg.start=fork'])
    with pytest.raises(ValueError, match=r"env_cfg.mp_cfg: 'start'"):
        test_tool.build_cfg(args)


@pytest.mark.parametrize('flag', ['--show', '--tta', '--wait-time=1'])
def test_test_py_offers_only_options_that_work(flag, capsys):
    """mmdet3d's --show (a window) and --tta (no config defines a test-time
    augmentation) only ended in tracebacks here; they are not offered, and
    argparse refuses them in one line. --show-dir, which works, stays."""
    with pytest.raises(SystemExit) as end:
        test_tool.parse_args([CONFIG, 'ckpt.pth', flag])
    assert end.value.code == 2
    assert 'unrecognized arguments' in capsys.readouterr().err
    args = test_tool.parse_args([CONFIG, 'ckpt.pth', '--show-dir', 'pics'])
    assert args.show_dir == 'pics'
