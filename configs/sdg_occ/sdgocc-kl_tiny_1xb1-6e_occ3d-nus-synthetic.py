# The tiny SDG-Fusion trained as SDG-KL: fusion teacher, FOAD distillation,
# camera-only inference head path.
_base_ = ['./sdgocc-fusion_tiny_1xb1-6e_occ3d-nus-synthetic.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

model = dict(
    variant='kl',
    distill_loss=dict(
        type='FOADDistillLoss', alpha=1.0, beta=1.0, loss_weight=1.0),
    teacher_loss_weight=1.0)
