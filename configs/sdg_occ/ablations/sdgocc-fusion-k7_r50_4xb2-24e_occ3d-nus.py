# SDG-OCC Table 5: 7x7 neighbourhood in the fusion attention (the paper's
# choice, = the main config).
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(fusion=dict(kernel_size=7))
