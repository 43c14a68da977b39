# SDG-OCC Table 5: 5x5 neighbourhood in the fusion attention.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

custom_imports = dict(
    imports=['projects.occ_common', 'projects.sdg_occ'],
    allow_failed_imports=False)

model = dict(fusion=dict(kernel_size=5))
