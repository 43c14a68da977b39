# The small SDG-KL (its student scored; sdgocc-kl_small_*.py) on the no-mask
# SDG-Fusion's supervision and metrics
# (sdgocc-fusion_small_*-nomask-synthetic.py).
_base_ = ['./_base_/sdgocc-fusion_small_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
model = dict(_base_.kl_model, loss_mask_key=None)
val_evaluator = test_evaluator = [
    _base_.val_evaluator, dict(_base_.ray_iou_metric, cache_gt_rays=True)]
