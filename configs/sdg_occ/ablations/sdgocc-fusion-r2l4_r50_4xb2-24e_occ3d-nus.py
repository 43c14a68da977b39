# SDG-OCC Table 4: r = 2 m, l = 4: 9 virtual points per pixel, 1/2 m
# apart over [d - 2, d + 2].
_base_ = ['../sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(view_transform=dict(layer_radius=2.0, num_layers=4))
