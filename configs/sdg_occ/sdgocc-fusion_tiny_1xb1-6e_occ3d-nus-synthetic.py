# A tiny SDG-Fusion that trains on CPU in a few minutes on the synthetic
# world's Occ3D labels (_base_/sdgocc-fusion_tiny.py): for smoke tests and
# the demo, not for accuracy.
_base_ = ['./_base_/sdgocc-fusion_tiny_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
