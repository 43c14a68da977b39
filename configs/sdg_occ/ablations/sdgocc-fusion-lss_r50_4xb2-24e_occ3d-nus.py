# SDG-OCC Table 3, baseline: SDG-Fusion with the plain LSS lift (no
# semantic diffusion, no virtual points) and no FOAD.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

model = dict(view_transform=dict(use_sdg=False, fallback='lss'))
