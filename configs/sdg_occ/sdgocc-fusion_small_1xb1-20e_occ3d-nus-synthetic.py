# The small SDG-Fusion of the held-out learning benchmark
# (_base_/sdgocc-fusion_small_occ3d-nus-synthetic.py says how it is sized).
_base_ = ['./_base_/sdgocc-fusion_small_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
