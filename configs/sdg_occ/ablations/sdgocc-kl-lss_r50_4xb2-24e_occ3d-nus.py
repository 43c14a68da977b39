# SDG-OCC Table 3, FOAD only: SDG-KL's distillation with the plain LSS
# lift instead of the SDG view transform.
_base_ = ['../sdgocc-kl_r50_4xb2-24e_occ3d-nus.py']

model = dict(view_transform=dict(use_sdg=False, fallback='lss'))
