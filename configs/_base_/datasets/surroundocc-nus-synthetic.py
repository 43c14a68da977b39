# surroundocc-nus.py on the synthetic nuScenes-format world. Build it with
#   python tools/create_synthetic_nuscenes.py data/nuscenes_synthetic
#   python tools/create_data.py nuscenes --root-path data/nuscenes_synthetic \
#       --version v1.0-mini
# (the converter recognises the world and splits its last scenes off as val).
_base_ = ['./surroundocc-nus.py']

data_root = 'data/nuscenes_synthetic/'

train_dataloader = dict(
    num_workers=2, dataset=dict(data_root=data_root))
val_dataloader = dict(
    num_workers=2, dataset=dict(data_root=data_root))
test_dataloader = val_dataloader
