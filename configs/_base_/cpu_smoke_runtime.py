# default_runtime.py for the tiny and small CPU configs: a log line per
# iteration, one checkpoint kept (a config saves it at its last epoch) and
# a fixed seed.
_base_ = ['./default_runtime.py']

default_hooks = dict(
    logger=dict(interval=1), checkpoint=dict(max_keep_ckpts=1))
# Each line shows its own iteration's loss: default_runtime's window of 50
# would log the running mean of the run so far, which hides whether the
# last iterations' loss is below the first ones'.
log_processor = dict(window_size=1)
randomness = dict(seed=0)
# Training on CPU frees and reallocates the same large activations every
# iteration; by default glibc hands each back to the kernel and faults it in
# again (~40 % of the small OccCylindrical's CPU time was page faults;
# projects/occ_common/engine/hooks/cpu_malloc_tuning_hook.py).
custom_hooks = _base_.custom_hooks + [dict(type='CPUMallocTuningHook')]
