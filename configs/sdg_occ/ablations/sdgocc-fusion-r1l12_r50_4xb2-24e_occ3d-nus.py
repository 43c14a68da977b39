# SDG-OCC Table 4: r = 1 m, l = 12: 25 virtual points per pixel, 1/12 m
# apart over [d - 1, d + 1].
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(view_transform=dict(layer_radius=1.0, num_layers=12))
