"""tools/demo.py: the table line that tells whether each large class was
learned."""
import argparse

from mmengine.config import Config, DictAction

from projects.occ_common.testing.tool_logs import load_tool


def test_unlearned_large_classes_needs_a_gain_of_five_points():
    """Large classes (>= 1,000 GT voxels): car 0.2 -> 30.0 gained; road
    40.0 -> 44.0 gained only 4 points; bicycle (300 voxels) is not large
    whatever its IoU; free is never listed."""
    demo = load_tool('demo.py')
    counts = {'occ/gt_voxels/car': 5000, 'occ/gt_voxels/road': 90000,
              'occ/gt_voxels/bicycle': 300, 'occ/gt_voxels/free': 10**6}
    row = dict(
        metrics=dict(counts, **{'occ/car': 30.0, 'occ/road': 44.0,
                                'occ/bicycle': 0.0, 'occ/free': 10.0}),
        untrained=dict(counts, **{'occ/car': 0.2, 'occ/road': 40.0,
                                  'occ/bicycle': 0.0, 'occ/free': 50.0}))
    assert demo.unlearned_large_classes(row) == 'road'
    row['metrics']['occ/road'] = 45.0
    assert demo.unlearned_large_classes(row) == 'none'


def test_schedule_options_stretch_the_cosine_to_the_epochs():
    """The small OccCylindrical config decays its LR by a cosine over its
    12 epochs (scheduler 1) after a 50-iteration warm-up (scheduler 0,
    iteration-based). Trained 3 epochs, the cosine must end at epoch 3
    (not leave the run at a barely decayed rate); trained 30, at epoch 30
    (not train 18 epochs at 0). Applied the way tools/train.py applies
    --cfg-options, only the cosine's end and T_max and the loop change."""
    demo = load_tool('demo.py')
    config = ('configs/occ_cyl/'
              'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py')
    assert demo.schedule_options(config, None)[0] == 12
    for epochs in (3, 30):
        got, options = demo.schedule_options(config, epochs)
        assert got == epochs
        parser = argparse.ArgumentParser()
        parser.add_argument('opts', nargs='*', action=DictAction)
        cfg = Config.fromfile(config, import_custom_modules=False)
        before = cfg.param_scheduler[0].copy()
        cfg.merge_from_dict(parser.parse_args(options).opts)
        cosine = cfg.param_scheduler[1]
        assert (cosine.end, cosine.T_max) == (epochs, epochs)
        assert cosine.type == 'CosineAnnealingLR'
        assert cfg.param_scheduler[0] == before
        assert cfg.train_cfg.max_epochs == epochs
        assert cfg.train_cfg.val_interval == epochs
        assert cfg.default_hooks.checkpoint.interval == epochs
