"""demo/synthetic_demo.py: the table line that tells whether each large class
was learned."""
import argparse

from mmengine.config import Config, DictAction

from projects.occ_common.datasets.converters import nuscenes_occ_converter
from projects.occ_common.testing.tool_logs import load_tool


def test_unlearned_large_classes_needs_a_gain_of_five_points():
    """Large classes (>= 1,000 GT voxels): car 0.2 -> 30.0 gained; road
    40.0 -> 44.0 gained only 4 points; bicycle (300 voxels) is not large
    whatever its IoU; free is never listed."""
    demo = load_tool('demo/synthetic_demo.py')
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


def test_schedule_options_stretch_the_schedule_to_the_epochs():
    """The small OccCylindrical config warms up over 50 iterations
    (scheduler 0) and decays its LR by a cosine over its 12 epochs
    (scheduler 1). Trained 3 epochs (a quarter), the cosine must end at
    epoch 3, not leave the run at a barely decayed rate, and the warm-up
    take round(12.5) = 12 iterations; trained 30 (2.5x), the cosine ends at
    epoch 30 (not 18 epochs at 0) and the warm-up takes 125. Applied the way
    tools/train.py applies --cfg-options."""
    demo = load_tool('demo/synthetic_demo.py')
    config = ('configs/occ_cyl/'
              'occcyl_small_1xb1-12e_surroundocc-nus-synthetic.py')
    for epochs, warmup in ((3, 12), (30, 125)):
        options = demo.schedule_options(config, epochs)
        parser = argparse.ArgumentParser()
        parser.add_argument('opts', nargs='*', action=DictAction)
        cfg = Config.fromfile(config, import_custom_modules=False)
        cfg.merge_from_dict(parser.parse_args(options).opts)
        linear, cosine = cfg.param_scheduler
        assert (linear.type, linear.begin, linear.end) == ('LinearLR', 0,
                                                           warmup)
        assert linear.by_epoch is False
        assert cosine.type == 'CosineAnnealingLR'
        assert (cosine.begin, cosine.end, cosine.T_max) == (0, epochs,
                                                            epochs)
        assert cfg.train_cfg.max_epochs == epochs
        assert cfg.train_cfg.val_interval == epochs
        assert cfg.default_hooks.checkpoint.interval == epochs


def test_schedule_options_scale_milestones():
    """A list-valued time, the paper OccCylindrical's MultiStepLR milestones
    [20, 23] of 24 epochs, travels as one shell word that mmengine reads
    back as a list: at 12 epochs [10, 12] (23 * 0.5 = 11.5 rounds to 12)
    and the 500-iteration warm-up 250."""
    demo = load_tool('demo/synthetic_demo.py')
    config = 'configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py'
    options = demo.schedule_options(config, 12)
    assert 'param_scheduler.1.milestones=[10,12]' in options
    parser = argparse.ArgumentParser()
    parser.add_argument('opts', nargs='*', action=DictAction)
    cfg = Config.fromfile(config, import_custom_modules=False)
    cfg.merge_from_dict(parser.parse_args(options).opts)
    assert cfg.param_scheduler[1].milestones == [10, 12]
    assert cfg.param_scheduler[1].end == 12
    assert cfg.param_scheduler[0].end == 250


def test_default_demo_trains_384_and_240_iterations_on_24_samples():
    """The README's demo schedule: 5 scenes x 6 key frames, of which the
    converter holds out the last max(1, 5 // 5) = 1 scene, leave 4 x 6 = 24
    training samples; OccCylindrical's 16 demo epochs are 384 iterations
    (batch 1) and SDG-Fusion's 10 are 240. Each model gets its own epochs
    (not its config's 12 and 20); ``--epochs`` overrides them for the
    models that ``--models`` picks."""
    demo = load_tool('demo/synthetic_demo.py')
    args = demo.parse_args([])
    scenes = [f'scene-{i:04d}' for i in range(args.scenes)]
    split = nuscenes_occ_converter.split_scenes(
        scenes, 'v1.0-mini', synthetic=True)
    train_samples = len(split['train']) * args.samples
    assert train_samples == 24
    iterations = {}
    for name, config, _, epochs in demo.selected_models(args):
        batch = Config.fromfile(config).train_dataloader.batch_size
        iterations[name] = epochs * train_samples // batch
    assert iterations == {'OccCylindrical': 384, 'SDG-Fusion': 240}
    quick = demo.parse_args(['--epochs', '4', '--models', 'SDG-Fusion'])
    assert [(m[0], m[3]) for m in demo.selected_models(quick)] == [
        ('SDG-Fusion', 4)]
