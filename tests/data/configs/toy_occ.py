# A toy occupancy config for the tests of tools/train.py and tools/test.py:
# a 1x1x1 conv on 8x8x4 grids trains in seconds on CPU.
_base_ = ['../../../configs/_base_/default_runtime.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.occ_common.testing.toy_model'],
    allow_failed_imports=False)

class_names = ['empty', 'car', 'road']
num_classes = len(class_names)

model = dict(
    type='ToyOccupancyModel', in_channels=num_classes,
    num_classes=num_classes)

train_dataloader = dict(
    batch_size=2,
    num_workers=0,
    sampler=dict(type='DefaultSampler', shuffle=True),
    dataset=dict(
        type='ToyOccupancyDataset', num_samples=8, num_classes=num_classes))
val_dataloader = dict(
    batch_size=2,
    num_workers=0,
    sampler=dict(type='DefaultSampler', shuffle=False),
    dataset=dict(
        type='ToyOccupancyDataset',
        num_samples=4,
        num_classes=num_classes,
        seed=100))
test_dataloader = val_dataloader

val_evaluator = dict(
    type='OccupancyMetric', convention='surroundocc', class_names=class_names)
test_evaluator = val_evaluator

train_cfg = dict(type='EpochBasedTrainLoop', max_epochs=2, val_interval=1)
val_cfg = dict(type='ValLoop')
test_cfg = dict(type='TestLoop')

optim_wrapper = dict(
    type='OptimWrapper', optimizer=dict(type='SGD', lr=0.5, momentum=0.9))
param_scheduler = [
    dict(type='MultiStepLR', by_epoch=True, milestones=[1], gamma=0.5)
]

default_hooks = dict(logger=dict(interval=1))
randomness = dict(seed=0)
