# SDG-OCC Table 3, baseline: SDG-Fusion with the plain LSS lift (no
# semantic diffusion, no virtual points) and no FOAD.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(view_transform=dict(use_sdg=False, fallback='lss'))
