# SDG-OCC Table 4: virtual points spread over [d - 1, d + 1] m in
# 4 layers.
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(view_transform=dict(layer_radius=1.0, num_layers=4))
