# Tiny SDG-Fusion, synthetic 4-camera rig, no ring: customize_dataset.md
_base_ = ['./_base_/sdgocc-fusion_tiny_occ3d-nus-synthetic.py',
          '../_base_/cpu_smoke_runtime.py']

default_hooks = dict(checkpoint=dict(interval=_base_.max_epochs))
cam_names, data_root = _base_._quad['cam_names'], _base_._quad['data_root']
train_dataloader = val_dataloader = test_dataloader = dict(
    dataset=_base_._quad)
