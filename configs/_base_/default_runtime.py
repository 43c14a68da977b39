# Runtime shared by every config of this library (mmdet3d 1.x conventions).
default_scope = 'mmdet3d'

default_hooks = dict(
    timer=dict(type='IterTimerHook'),
    logger=dict(type='LoggerHook', interval=50),
    param_scheduler=dict(type='ParamSchedulerHook'),
    checkpoint=dict(type='CheckpointHook', interval=1, max_keep_ckpts=3),
    sampler_seed=dict(type='DistSamplerSeedHook'))

# Writes checkpoints that load with torch.load(weights_only=True); see
# projects/occ_common/hooks/weights_only_checkpoint_hook.py.
custom_hooks = [dict(type='WeightsOnlyCheckpointHook')]

env_cfg = dict(
    cudnn_benchmark=False,
    mp_cfg=dict(mp_start_method='fork', opencv_num_threads=0),
    # gloo also runs on CPU-only machines; CUDA users may override to nccl.
    dist_cfg=dict(backend='gloo'))

log_processor = dict(type='LogProcessor', window_size=50, by_epoch=True)

log_level = 'INFO'
load_from = None
resume = False
