# Runtime shared by every config of this library (mmdet3d 1.x conventions);
# each hook of ours says why in its module (projects/occ_common/engine/hooks/).
default_scope = 'mmdet3d'

default_hooks = dict(
    timer=dict(type='IterTimerHook'),
    # LoggerHook whose metrics json only rank 0 writes (under dist_test.sh
    # every rank rewrote it at once and could leave it unparseable).
    logger=dict(type='MainProcessLoggerHook', interval=50),
    param_scheduler=dict(type='ParamSchedulerHook'),
    # Atomic saves, read back before the oldest goes: a kill, Ctrl-C or full
    # disk never leaves fewer than one complete checkpoint.
    checkpoint=dict(type='SafeCheckpointHook', interval=1, max_keep_ckpts=3),
    sampler_seed=dict(type='DistSamplerSeedHook'),
    # Off until tools/test.py --show-dir DIR sets draw=True: then one
    # picture (GT, prediction, error; top-down and 3D) per evaluated sample.
    visualization=dict(type='OccVisualizationHook', draw=False))

custom_hooks = [
    # Checkpoints (zoo ones included) load through a restricted unpickler
    # that refuses any pickled code.
    dict(type='WeightsOnlyCheckpointHook'),
    # Stops at the first NaN / inf loss term or gradient norm and never saves
    # non-finite weights, keeping the last good checkpoint.
    dict(type='NonFiniteLossHook'),
    # --resume drops partial writes and resumes from the newest complete
    # checkpoint, with or without a last_checkpoint pointer.
    dict(type='CheckpointRecoveryHook'),
    # Augmentation seeded by (seed, epoch, index) and every rank's random
    # state saved in each checkpoint: a resumed run repeats an uninterrupted
    # one exactly (DropPath and dropout included).
    dict(type='AugmentationSeedHook'),
    dict(type='RandomStateHook'),
    # With `compile=True` (mmengine compiles train_step): val/test steps
    # compiled too, and every cloud's point count marked dynamic, so a new
    # count recompiles nothing. Without `compile` it does nothing.
    dict(type='TorchCompileHook')]

# Where the Runner's pictures and scalars go (also mmdet3d's
# tools/misc/browse_dataset.py); for TensorBoard add
# dict(type='TensorboardVisBackend') (docs/visualization.md).
vis_backends = [dict(type='LocalVisBackend')]
# No `name`: the Runner names each run's visualizer after the run.
visualizer = dict(type='OccLocalVisualizer', vis_backends=vis_backends)

env_cfg = dict(
    cudnn_benchmark=False,
    mp_cfg=dict(mp_start_method='fork', opencv_num_threads=0),
    # nccl, mmdet3d's default for CUDA; without CUDA tools/train.py and
    # tools/test.py use gloo (projects/occ_common/engine/cpu_dist.py).
    dist_cfg=dict(backend='nccl'))
log_processor = dict(type='LogProcessor', window_size=50, by_epoch=True)
log_level = 'INFO'
load_from = None
resume = False
