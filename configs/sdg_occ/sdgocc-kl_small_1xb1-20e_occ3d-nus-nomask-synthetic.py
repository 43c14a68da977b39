# The small SDG-KL (its student scored) on the synthetic world's Occ3D
# labels, trained without the camera mask and scored with RayIoU beside the
# camera-mask mIoU: sdgocc-kl_small_*.py's model on the no-mask SDG-Fusion's
# data and metrics.
_base_ = ['./sdgocc-fusion_small_1xb1-20e_occ3d-nus-nomask-synthetic.py']

model = dict(_base_.kl_model, loss_mask_key=None)
