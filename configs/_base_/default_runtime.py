# Runtime shared by every config of this library (mmdet3d 1.x conventions).
default_scope = 'mmdet3d'

default_hooks = dict(
    timer=dict(type='IterTimerHook'),
    logger=dict(type='LoggerHook', interval=50),
    param_scheduler=dict(type='ParamSchedulerHook'),
    # backend_args: write each .pth atomically (temp file + fsync + rename),
    # so a crash while saving never leaves a truncated checkpoint; see
    # projects/occ_common/hooks/atomic_file_backend.py.
    checkpoint=dict(
        type='CheckpointHook',
        interval=1,
        max_keep_ckpts=3,
        backend_args=dict(backend='atomic_local')),
    sampler_seed=dict(type='DistSamplerSeedHook'),
    # Off until tools/test.py --show-dir DIR sets draw=True: then one
    # picture (GT, prediction, error; top-down and 3D) per evaluated sample.
    visualization=dict(type='OccVisualizationHook', draw=False))

custom_hooks = [
    # Writes checkpoints that load with torch.load(weights_only=True); see
    # projects/occ_common/hooks/weights_only_checkpoint_hook.py.
    dict(type='WeightsOnlyCheckpointHook'),
    # Stops at the first NaN / inf loss term, naming the iteration and the
    # term, before CheckpointHook can save or rotate checkpoints.
    dict(type='NonFiniteLossHook'),
    # Before resuming: removes partial writes and repairs an empty
    # last_checkpoint left by a crash.
    dict(type='CheckpointRecoveryHook'),
]

env_cfg = dict(
    cudnn_benchmark=False,
    mp_cfg=dict(mp_start_method='fork', opencv_num_threads=0),
    # gloo also runs on CPU-only machines; CUDA users may override to nccl.
    dist_cfg=dict(backend='gloo'))

log_processor = dict(type='LogProcessor', window_size=50, by_epoch=True)

log_level = 'INFO'
load_from = None
resume = False
