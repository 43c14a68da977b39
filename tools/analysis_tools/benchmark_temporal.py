"""Benchmark SDG-OCC over two key frames: latency with and without the cache.

Builds the model of a temporal config (default: the tiny two-frame
SDG-Fusion) three ways, with the same weights: T = 1 (``num_frames=1``),
T = 2 recomputing the previous frame's camera BEV, and T = 2 with the
test-time cache (each frame's BEV reused by the next, as on a sequential
test loader). Each runs ``mode='predict'`` over one synthetic scene of
``--frames`` key frames (``make_temporal_scene``: random images, the
cameras of ``make_occ_batch``); the three alternate within each round, and
the per-frame medians over ``--rounds`` rounds are reported (CPU time of
the process, less sensitive to other jobs than wall time, and wall time).

Example::

    python tools/analysis_tools/benchmark_temporal.py --rounds 5 --out \\
        temporal.json

Like the other tools it imports no plugin code itself: the config's
``custom_imports`` register it (and ``projects.occ_common.synthetic``
gives the synthetic scene).
"""
import argparse
import json
import os.path as osp
import statistics

import torch
from mmdet3d.registry import MODELS
from mmengine.config import Config
from mmengine.registry import init_default_scope
from mmengine.utils import import_modules_from_strings

from projects.occ_common.analysis.benchmarking import timed_runs

ROOT = osp.dirname(
    osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = 'configs/sdg_occ/sdgocc-fusion-2f_tiny_1xb1-6e_occ3d-nus-synthetic.py'


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', default=CONFIG, help='a T = 2 config')
    parser.add_argument(
        '--frames', type=int, default=4, help='key frames of the scene')
    parser.add_argument(
        '--rounds', type=int, default=3, help='timed rounds per model')
    parser.add_argument(
        '--cams', type=int, default=6, help='cameras per frame')
    parser.add_argument(
        '--img-shape', type=int, nargs=2, default=(128, 352),
        help='image H W')
    parser.add_argument('--threads', type=int, default=0,
                        help='torch CPU threads (0: keep)')
    parser.add_argument('--out', help='write the results as JSON here')
    return parser.parse_args(argv)


def build(cfg, **overrides):
    """The config's model with ``overrides``, seeded, in eval mode."""
    torch.manual_seed(0)
    return MODELS.build(dict(cfg.model, **overrides)).eval()


def main(argv=None):
    """Run the benchmark and print (optionally write) the medians."""
    args = parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    cfg = Config.fromfile(osp.join(ROOT, args.config))
    cfg.model.img_backbone.init_cfg = None
    import_modules_from_strings(**cfg.custom_imports)
    testing = import_modules_from_strings(
        'projects.occ_common.synthetic.occ_inputs')
    init_default_scope(cfg.default_scope)
    if cfg.model.get('num_frames', 1) != 2:
        raise ValueError(f'{args.config} is not a two-frame config')
    pcr = cfg.model.point_cloud_range
    scene = testing.make_temporal_scene(
        args.frames, num_cams=args.cams, img_shape=tuple(args.img_shape),
        num_points=(2000, ), occ_shape=(1, 1, 1), pc_range=pcr)
    models = dict(
        t1=build(cfg, num_frames=1),
        t2_uncached=build(cfg, test_cache=False),
        t2_cached=build(cfg, test_cache=True))
    views = args.cams

    def run(name):
        model = models[name]
        model.bev_cache.clear()  # a new scene
        for inputs, samples in scene:
            if name == 't1':
                inputs = dict(inputs, imgs=inputs['imgs'][:, :views])
            model(inputs, samples, mode='predict')

    times = {name: dict(wall_s=[], cpu_s=[]) for name in models}
    with torch.no_grad():
        for name in models:
            run(name)  # warm-up
        for _ in range(args.rounds):
            for name in models:
                got = timed_runs(lambda: run(name), 1)
                for key in got:
                    times[name][key].extend(
                        t / args.frames for t in got[key])
    result = {
        name: {key: statistics.median(v)
               for key, v in per.items()}
        for name, per in times.items()
    }
    result['setup'] = dict(
        config=args.config, frames=args.frames, rounds=args.rounds,
        cams=args.cams, img_shape=list(args.img_shape),
        threads=torch.get_num_threads(),
        cache_hits=models['t2_cached'].bev_cache.hits)
    print(json.dumps(result, indent=1))
    if args.out:
        with open(args.out, 'w') as f:
            json.dump(result, f, indent=1)


if __name__ == '__main__':
    main()
