"""Tests of the contract both occupancy detectors share."""
import pytest
import torch
from mmdet3d.registry import MODELS
from mmdet3d.utils import register_all_modules

import projects.occ_common  # noqa: F401 (registers the losses)
from projects.occ_common.models.detectors import BaseOccDetector
from projects.occ_common.synthetic.occ_inputs import make_occ_batch

register_all_modules(init_default_scope=False)


class _Detector(BaseOccDetector):
    """The base with an occupancy loss of its own: a 1x1x1 'head' whose
    logits are a learnt constant per class, so the loss sees exactly the
    targets the base prepares."""

    def __init__(self, loss_occ=None, **kwargs):
        super().__init__(
            point_cloud_range=(-8.0, -8.0, -2.0, 8.0, 8.0, 2.0),
            voxel_size=(2.0, 2.0, 1.0),
            num_classes=4,
            **kwargs)
        self.logit = torch.nn.Parameter(torch.zeros(self.num_classes))
        self.loss_occ = self.build_child(
            loss_occ or dict(
                type='OccupancyLoss',
                losses=[dict(type='OccFocalLoss', gamma=0.0)]),
            empty_index=self.empty_index,
            ignore_index=self.ignore_index)

    def _logits(self, batch_size):
        return self.logit.view(1, -1, 1, 1, 1).expand(
            batch_size, -1, *self.occ_shape)

    def extract_feat(self, inputs, data_samples):
        """The constant logits. Shape (B, C, X, Y, Z)."""
        return self._logits(len(data_samples))

    def loss(self, inputs, data_samples):
        """The occupancy loss on the masked targets."""
        targets = self.occupancy_targets(data_samples, self.logit.device)
        return self.loss_occ(self.extract_feat(inputs, data_samples),
                             targets)

    def predict(self, inputs, data_samples):
        """Argmax of the constant logits."""
        return self.add_pred_occ(
            data_samples,
            self.extract_feat(inputs, data_samples).argmax(1))

    def _forward(self, inputs, data_samples):
        return self.extract_feat(inputs, data_samples)


def test_grid_and_head_defaults():
    """16 m / 2 m = 8 cells in x and y, 4 m / 1 m = 4 in z."""
    det = _Detector(empty_index=3, ignore_index=9)
    assert det.occ_shape == (8, 8, 4)
    assert det.head_defaults() == dict(
        num_classes=4, empty_index=3, ignore_index=9)


def test_camera_mask_is_applied_once_here():
    """With loss_mask_key the voxels outside the mask become ignore_index:
    an all-False mask leaves nothing to supervise (loss exactly 0), an
    all-True one the labels as they are."""
    _, samples = make_occ_batch(batch_size=2)
    det = _Detector(loss_mask_key='mask_camera')
    masked = det.occupancy_targets(samples, torch.device('cpu'))
    keep = torch.stack([s.mask_camera for s in samples])
    gt = torch.stack([s.gt_occ for s in samples])
    assert torch.equal(masked[keep], gt[keep])
    assert bool((masked[~keep] == 255).all())
    for sample in samples:
        sample.mask_camera[:] = False
    assert det.loss(None, samples)['loss_focal'].item() == 0.0
    unmasked = _Detector().occupancy_targets(samples, torch.device('cpu'))
    assert torch.equal(unmasked, gt)


def test_gt_depth_is_padded_like_the_images():
    """(2, 32, 64) maps padded to a (40, 64) input: 8 zero rows below."""
    _, samples = make_occ_batch(batch_size=1)
    det = _Detector()
    depth = det.gt_depth(samples, torch.device('cpu'), (40, 64))
    assert depth.shape == (2, 40, 64)
    assert torch.equal(depth[:, :32], samples[0].gt_depth.float())
    assert not bool(depth[:, 32:].any())
    with pytest.raises(ValueError, match='larger than the input'):
        det.gt_depth(samples, torch.device('cpu'), (16, 64))


def test_shared_values_reach_children_and_conflicts_are_refused():
    """loss_depth gets the detector's depth_bound; a child built with
    other labels or bins is named."""
    det = _Detector(
        depth_bound=(1.0, 9.0, 1.0),
        loss_depth=dict(type='DepthBCELoss', downsample=16))
    assert det.loss_depth.depth_bound == (1.0, 9.0, 1.0)
    assert det.depth_losses(torch.zeros(1, 8, 2, 4),
                            torch.zeros(1, 32, 64)).keys() == {'loss_depth'}
    assert _Detector().depth_losses(None, None) == {}
    with pytest.raises(ValueError, match='has depth_bound'):
        det.check_child(
            MODELS.build(
                dict(type='DepthBCELoss', depth_bound=(1.0, 9.0, 2.0))),
            depth_bound=det.depth_bound)
    with pytest.raises(ValueError, match='empty_index 4 is not one'):
        _Detector(empty_index=4)


def test_missing_fields_are_named():
    """A sample without gt_occ or a metainfo key names itself."""
    _, samples = make_occ_batch(batch_size=2)
    det = _Detector()
    del samples[1].gt_occ
    with pytest.raises(ValueError, match="data sample 1 has no 'gt_occ'"):
        det.occupancy_targets(samples, torch.device('cpu'))
    samples[0].set_metainfo(dict(sample_idx='tok0'))
    meta = dict(samples[0].metainfo)
    del meta['cam2img']
    bare = type(samples[0])(metainfo=meta)
    with pytest.raises(ValueError, match="tok0 has no metainfo 'cam2img'"):
        det.camera_params([bare], torch.device('cpu'))
    wrong = make_occ_batch(occ_shape=(4, 4, 4))[1]
    with pytest.raises(ValueError, match='does not match the grid'):
        det.occupancy_targets(wrong, torch.device('cpu'))


def test_seg_loss_counts_non_ignored_labels_without_a_host_read(
        monkeypatch):
    """mmdet's CrossEntropyLoss(avg_non_ignore=True) counts the labels it
    does not ignore with ``.item()`` (a sync; a graph break under
    torch.compile); the detector gives it that count as ``avg_factor``
    instead. Four pixels, two classes, logits 0 (CE ln 2 each), one label
    ignored: the mean over the other three is ln 2 = 0.6931472 (over all
    four it would be 0.75 ln 2), and Dynamo traces it in one graph."""
    from projects.occ_common.analysis.compile_check import explain_breaks
    det = _Detector(loss_seg=dict(
        type='mmdet.CrossEntropyLoss', ignore_index=255,
        avg_non_ignore=True))
    monkeypatch.setattr(det, 'seg_targets',
                        lambda *args: torch.tensor([[[0, 1], [255, 1]]]))
    logits = torch.zeros(1, 2, 2, 2)

    def loss(seg_logits):
        return det.seg_losses({'seg_logits': seg_logits}, [], None,
                              1)['loss_seg']

    assert loss(logits).item() == pytest.approx(0.6931472, abs=1e-6)
    report = explain_breaks(loss, logits)
    assert (report.graphs, report.breaks) == (1, [])
