# Runtime shared by every config of this library (mmdet3d 1.x conventions).
default_scope = 'mmdet3d'

default_hooks = dict(
    timer=dict(type='IterTimerHook'),
    # mmengine's LoggerHook, but only rank 0 writes the test metrics json:
    # under dist_test.sh every rank rewrote it at once and could leave it
    # unparseable; see
    # projects/occ_common/engine/hooks/main_process_logger_hook.py
    logger=dict(type='MainProcessLoggerHook', interval=50),
    param_scheduler=dict(type='ParamSchedulerHook'),
    # Writes each .pth atomically, reads it back, and only then deletes the
    # oldest: a kill, Ctrl-C or full disk during a save never leaves fewer
    # than one complete checkpoint; see
    # projects/occ_common/engine/hooks/safe_checkpoint_hook.py.
    checkpoint=dict(type='SafeCheckpointHook', interval=1, max_keep_ckpts=3),
    sampler_seed=dict(type='DistSamplerSeedHook'),
    # Off until tools/test.py --show-dir DIR sets draw=True: then one
    # picture (GT, prediction, error; top-down and 3D) per evaluated sample.
    visualization=dict(type='OccVisualizationHook', draw=False))

custom_hooks = [
    # Loads checkpoints (zoo ones included) with a restricted unpickler that
    # refuses any pickled code; see
    # projects/occ_common/engine/hooks/weights_only_checkpoint_hook.py.
    dict(type='WeightsOnlyCheckpointHook'),
    # Stops at the first NaN / inf loss term or gradient norm, and refuses
    # to save non-finite weights, naming the iteration and the term and
    # keeping the last good checkpoint.
    dict(type='NonFiniteLossHook'),
    # --resume: removes partial writes and resumes from the newest complete
    # checkpoint, with or without a last_checkpoint pointer.
    dict(type='CheckpointRecoveryHook'),
    # Seeds each sample's random augmentation by (seed, epoch, index), so a
    # resumed run repeats an uninterrupted one exactly.
    dict(type='AugmentationSeedHook'),
    # Saves the global random state (torch CPU / CUDA, numpy, Python) of
    # every rank in each checkpoint and restores it on --resume, so that
    # DropPath and dropout draw what an uninterrupted run draws.
    dict(type='RandomStateHook'),
]

# Where the Runner's pictures and scalars go; mmdet3d's
# tools/misc/browse_dataset.py draws samples through this visualizer too.
# TensorBoard (needs `pip install tensorboard`): add
# dict(type='TensorboardVisBackend') to vis_backends (docs/visualization.md).
vis_backends = [dict(type='LocalVisBackend')]
# No `name`: the Runner names each run's visualizer after the run.
visualizer = dict(type='OccLocalVisualizer', vis_backends=vis_backends)

env_cfg = dict(
    cudnn_benchmark=False,
    mp_cfg=dict(mp_start_method='fork', opencv_num_threads=0),
    # nccl, mmdet3d's default and the backend for CUDA tensors. On a
    # machine without CUDA, tools/train.py and tools/test.py run the ranks
    # with gloo instead (projects/occ_common/engine/cpu_dist.py), since nccl
    # needs GPUs.
    dist_cfg=dict(backend='nccl'))

log_processor = dict(type='LogProcessor', window_size=50, by_epoch=True)

log_level = 'INFO'
load_from = None
resume = False
