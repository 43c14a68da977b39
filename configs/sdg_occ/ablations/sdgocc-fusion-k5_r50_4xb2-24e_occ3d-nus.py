# SDG-OCC Table 5: 5x5 neighbourhood in the fusion attention.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(fusion=dict(kernel_size=5))
