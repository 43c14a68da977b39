# SDG-KL (sdgocc-kl_r50_4xb2-24e_occ3d-nus.py) trained without the camera
# mask and scored with RayIoU, as sdgocc-fusion_r50_4xb2-24e_occ3d-nus-nomask
# .py is SDG-Fusion.
_base_ = ['./sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py']

model = dict(_base_.kl_model, loss_mask_key=None)
val_evaluator = test_evaluator = [_base_.val_evaluator, _base_.ray_iou_metric]
