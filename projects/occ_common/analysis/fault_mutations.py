"""One-line regressions of the library's guards, for the fault matrix's
mutation check: each must turn at least one case of the matrix red.

A mutation names the function holding a guard, the line (text found once
in it) and what the line becomes: the guard removed, its condition never
true. ``tools/analysis_tools/fault_matrix.py --mutations`` runs, for each,
the cases whose ``guards`` list it, with the mutation made in the child
(:func:`~.source_mutation.mutate`); a mutation none of them notices is a
guard no case reaches. The names writers check before they write are
guarded by ``tests/occ_common/fileio/test_safe_names.py`` instead, which
fails on a writer without the check.
"""
from typing import Dict, NamedTuple


class Mutation(NamedTuple):
    """A one-line change of ``target`` (``'module:qualname'``)."""
    target: str
    old: str
    new: str


_PICKLE = 'projects.occ_common.fileio.safe_pickle'
_CHECKS = 'projects.occ_common.datasets.sample_checks'
_HOOKS = 'projects.occ_common.engine.hooks'
_RAY = 'projects.occ_common.evaluation.ray_iou_metric:RayIoUMetric'

#: Name (as cases list it in ``guards``) -> mutation.
MUTATIONS: Dict[str, Mutation] = {
    'TorchScript refused': Mutation(
        f'{_PICKLE}:load_checkpoint_stream', 'if kind == TORCHSCRIPT:',
        'if False:'),
    'restricted unpickler': Mutation(
        f'{_PICKLE}:_find_allowed', 'if qualname in allowed:', 'if True:'),
    'zip CRC': Mutation(
        f'{_PICKLE}:load_checkpoint_stream',
        'check_zip_records(file, name)', 'None'),
    'config text dropped': Mutation(
        f'{_PICKLE}:load_checkpoint_stream',
        'drop_config_text(checkpoint, name)', 'None'),
    'init_model loads restricted': Mutation(
        'projects.occ_common.apis.inference:init_model',
        '        install_checkpoint_loader()', '        pass'),
    'init_model checks weights': Mutation(
        'projects.occ_common.apis.inference:init_model',
        'if checkpoint is not None:', 'if False:'),
    'pretrained loads restricted': Mutation(
        'projects.occ_common.models.pretrained:checkpoint_state_dict',
        "load_checkpoint_file(path, map_location='cpu')",
        "__import__('torch').load(path, map_location='cpu', "
        'weights_only=False)'),
    'resume checks the model': Mutation(
        f'{_HOOKS}.checkpoint_match_hook:CheckpointMatchHook.'
        'after_load_checkpoint', 'check_checkpoint_state(',
        '(lambda *args: None)('),
    'resume overrides': Mutation(
        f'{_HOOKS}.checkpoint_match_hook:CheckpointMatchHook.'
        'after_load_checkpoint',
        'changes = resumed_state_changes(runner, checkpoint)',
        'changes = []'),
    'later checkpoints kept': Mutation(
        f'{_HOOKS}.checkpoint_recovery_hook:check_no_later_checkpoint',
        'if later:', 'if False:'),
    'glob-safe listing': Mutation(
        'projects.occ_common.engine.checkpoint_steps:step_checkpoints',
        'sorted(os.listdir(folder))',
        "sorted(osp.basename(p) for p in __import__('glob').glob("
        "osp.join(folder, '*.pth')))"),
    'lock refuses': Mutation(
        'projects.occ_common.engine.run_lock:owner_gone',
        'if not process_alive(pid):', 'if True:'),
    'earlier run kept': Mutation(
        'projects.occ_common.engine.run_lock:_take',
        'earlier = [] if resume else earlier_run_files(work_dir)',
        'earlier = []'),
    'pointer not followed': Mutation(
        f'{_HOOKS}.safe_checkpoint_hook:SafeCheckpointHook.'
        '_save_checkpoint_with_step',
        'if is_main_process() and osp.islink(self._pointer(runner)):',
        'if False:'),
    'custom_imports imported': Mutation(
        'projects.occ_common.engine.config_checks:merge_cfg_options',
        'import_overridden_modules(cfg, options, option)', 'None'),
    'rendezvous deadline': Mutation(
        'projects.occ_common.engine.cpu_dist:setup_distributed',
        '        with rendezvous_deadline():\n'
        '            dist.init_process_group(',
        '        with open(os.devnull):\n'
        '            dist.init_process_group('),
    'info file checked': Mutation(
        'projects.occ_common.datasets.info_format:check_info_file',
        'if token in first_index:', 'if False:'),
    'sample token checked': Mutation(
        'projects.occ_common.datasets.single_sample:sample_info_file',
        "safe_file_name(infos['data_list'][chosen]['token'],",
        "(lambda token, *args: token)(infos['data_list'][chosen]['token'],"
    ),
    'prediction name checked': Mutation(
        'projects.occ_common.evaluation.occupancy_export:'
        'write_occ3d_prediction',
        "token = safe_file_name(sample_token, 'sample token')",
        'token = str(sample_token)'),
    'regular files only': Mutation(
        'projects.occ_common.fileio.input_files:read_input_bytes',
        'size = check_input_file(path, what, max_bytes)',
        'size = os.path.getsize(path)'),
    'label headers checked': Mutation(
        'projects.occ_common.fileio.input_files:load_npz_arrays',
        'wrong = check(name, shape, dtype)', 'wrong = None'),
    'ring column checked': Mutation(
        'projects.occ_common.transforms.points_loading:read_points_file',
        '        _check_ring_column(points, path, what)', '        pass'),
    'EXIF ignored': Mutation(
        'projects.occ_common.transforms.image_loading:'
        'LoadMultiViewImagesOcc.transform',
        'raw, flag=decode_flag(self.color_type))',
        'raw, flag=self.color_type)'),
    'finite timestamps': Mutation(
        f'{_CHECKS}:check_seconds', 'if not math.isfinite(value):',
        'if False:'),
    'sweeps before key frame': Mutation(
        f'{_CHECKS}:check_sweep_time', 'if sweep_time > key_time:',
        'if False:'),
    'rigid transforms': Mutation(
        f'{_CHECKS}:check_rigid', '    rot = mat[:3, :3]', '    return mat'),
    'previous frames checked': Mutation(
        f'{_CHECKS}:check_previous_time', 'if not 0 < gap <= MAX_FRAME_GAP:',
        'if False:'),
    'ray origins matched': Mutation(
        f'{_RAY}._origins', 'self._check_same_frame(sample, name, token)',
        'None'),
    'ray cache verified': Mutation(
        f'{_RAY}._cached', 'if stored != (key, _hits_digest(hits)):',
        'if False:'),
}

__all__ = ['MUTATIONS', 'Mutation']
