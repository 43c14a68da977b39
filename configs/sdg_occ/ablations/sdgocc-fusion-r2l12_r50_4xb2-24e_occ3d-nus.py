# SDG-OCC Table 4: virtual points spread over [d - 2, d + 2] m in
# 12 layers.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(view_transform=dict(layer_radius=2.0, num_layers=12))
