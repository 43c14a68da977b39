# The small SDG-Fusion trained as SDG-KL: fusion teacher, FOAD distillation,
# camera-only inference head path (kl_model of _base_/sdgocc-fusion_r50.py).
_base_ = ['./sdgocc-fusion_small_1xb1-20e_occ3d-nus-synthetic.py']

model = _base_.kl_model
