# occ3d-nus.py on the synthetic nuScenes-format world. Build it with
#   python tools/dataset_converters/create_synthetic_nuscenes.py \
#       data/nuscenes_synthetic
#   python tools/create_data.py nuscenes --root-path data/nuscenes_synthetic \
#       --version v1.0-mini
# (the converter recognises the world and splits its last scenes off as val).
_base_ = ['./occ3d-nus.py']

data_root = 'data/nuscenes_synthetic/'
# Worker processes only add start-up time on a world of a few samples;
# these configs train on the CPU, where there is no device memory to pin for.
_loader = dict(
    num_workers=0,
    persistent_workers=False,
    pin_memory=False,
    dataset=dict(data_root=data_root))
train_dataloader = _loader
val_dataloader = _loader
test_dataloader = val_dataloader
