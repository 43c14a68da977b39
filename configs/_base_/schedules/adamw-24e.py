# 24 epochs of AdamW with validation at the end, the recipe family of both
# papers' nuScenes models. A model base (configs/<project>/_base_/) inherits
# it and sets its learning rate, weight decay, clipping and warm-up.
max_epochs = 24
optim_wrapper = dict(type='OptimWrapper', optimizer=dict(type='AdamW'))
param_scheduler = []
train_cfg = dict(
    type='EpochBasedTrainLoop', max_epochs=max_epochs,
    val_interval=max_epochs)
val_cfg = dict(type='ValLoop')
test_cfg = dict(type='TestLoop')
