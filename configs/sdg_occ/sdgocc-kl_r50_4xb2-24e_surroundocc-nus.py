# SDG-KL (SDG-OCC, Duan et al., CVPR 2025) on SurroundOcc-nuScenes:
# SDG-Fusion's network trained with the fusion as a teacher and FOAD
# distillation into the camera BEV; inference skips the SPVCNN branch and
# the fusion.
_base_ = ['./sdgocc-fusion_r50_4xb2-24e_surroundocc-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

model = dict(
    variant='kl',
    # alpha, beta and the loss weight are not fixed by the paper: the
    # N_AR / N_IR balance already equalises the two regions, so both
    # regions start at weight 1.
    distill_loss=dict(
        type='FOADDistillLoss', alpha=1.0, beta=1.0, loss_weight=1.0),
    # The teacher must learn occupancy for its features to be worth
    # distilling; it gets the same weight as the student's head.
    teacher_loss_weight=1.0)
