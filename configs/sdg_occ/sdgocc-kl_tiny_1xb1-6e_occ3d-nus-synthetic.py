# The tiny SDG-Fusion trained as SDG-KL (kl_model of
# _base_/sdgocc-fusion_r50.py): fusion teacher, FOAD distillation,
# camera-only inference.
_base_ = ['./_base_/sdgocc-fusion_tiny_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
model = _base_.kl_model
