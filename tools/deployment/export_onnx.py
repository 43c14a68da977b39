"""Export a model's prediction path to ONNX and check it with onnxruntime.

Usage::

    python tools/deployment/export_onnx.py CONFIG CHECKPOINT --out FILE.onnx \\
        [--verify SAMPLE ...] [--sample-idx N | --sample-token TOKEN] \\
        [--data-root DIR] [--export-seed S] [--opset N] \\
        [--latency ROUNDS] [--threads T] [--cfg-options KEY=VALUE ...]

    # SDG-KL: the whole prediction path in one graph, checked on two
    # synthetic samples of other rigs and point counts and a real one
    python tools/deployment/export_onnx.py \\
        configs/sdg_occ/sdgocc-kl_r50_4xb2-24e_occ3d-nus.py sdgocc-kl.pth \\
        --out work_dirs/sdgocc-kl.onnx --verify synthetic:1 synthetic:2 \\
        data/nuscenes/nuscenes_infos_val.pkl --data-root data/nuscenes

What is exported (docs/export.md):

* SDG-KL and SDG-OCC's camera rows: images, the camera matrices of the
  metainfo (``cam2img``, ``lidar2cam``, ``img_aug_matrix``, ``lidar2img``)
  and the LiDAR points (any number) in, occupancy logits and labels out;
  the data preprocessor's normalisation, every inverse, the depth map, the
  virtual points and the BEV pooling are in the graph.
* SDG-Fusion: the same plus the fusion, with the SPVCNN LiDAR BEV as an
  input that PyTorch computes beside the runtime (the JSON says so).
* OccCylindrical: two graphs, ``FILE.onnx`` (the fused TPV planes -> plane
  encoder -> head -> occupancy) and ``FILE.camera.onnx`` (images ->
  DepthNet's depth and context; the paper configs' DCNv2 layers as ONNX
  ``DeformConv``, opset 19); the point branch and TPV-Polar-Fusion
  between them run in PyTorch (the JSON and docs/export.md say why).

The graph is traced with one synthetic sample of the config's shapes
(``--export-seed``, default 0) on the GPU code path, by the TorchScript
exporter. ``FILE.json`` beside it records the inputs (names, shapes,
meaning), the outputs, what runs outside the graph, the node count, and
the parity of every ``--verify`` sample: ``synthetic:SEED[:POINTS]`` (a
synthetic sample with another rig and, by default, another point count
than the exported one) or an info file (this library's or an mmdet3d v2
one, read through the config's test pipeline as ``demo/occ_demo.py`` reads
it; ``--sample-idx`` / ``--sample-token`` / ``--data-root`` apply to it).
A sample passes when the logits are within ``--atol`` (1e-3) of
PyTorch's (the model's own ``_forward`` on its default path) and the
argmax agrees on at least ``--min-agreement`` (99.9 %) of the voxels (a
further graph: its outputs within ``--atol`` of its PyTorch module's); the
exit status is 1 when one does not. ``--latency ROUNDS`` times
onnxruntime against PyTorch on the CPU, in alternating rounds, on the
first ``--verify`` sample.

CHECKPOINT ``none`` exports the freshly built model (no weights loaded,
no download): a graph to measure, not to deploy.
"""
import argparse
import json
import os.path as osp
import sys
import tempfile
import time
from typing import Dict, List

import torch

#: Verification thresholds (fp32), set with the export (2026-11-28).
ATOL = 1e-3
MIN_AGREEMENT = 0.999
#: What each graph input is, for FILE.json.
INPUT_DOCS = dict(
    imgs='the pipeline\'s images, pixel values 0-255 in its channel order '
    '(the graph normalises and pads them)',
    points='LiDAR points (x, y, z, ...) in the working frame, any number',
    cam2img='intrinsics padded to 4x4',
    lidar2cam='working frame to camera',
    img_aug_matrix='image augmentation (resize, crop, flip, rotation)',
    lidar2img='img_aug_matrix @ cam2img @ lidar2cam, as the metainfo holds '
    'it',
    lidar_bev='the LiDAR encoder\'s BEV of the same points',
    plane_r_theta='fused TPV plane (R, Theta) of TPV-Polar-Fusion',
    plane_theta_z='fused TPV plane (Theta, Z)',
    plane_r_z='fused TPV plane (R, Z)')


def parse_args(argv=None):
    """Parse the command line."""
    parser = argparse.ArgumentParser(
        description='Export a model to ONNX and verify it with onnxruntime')
    parser.add_argument('config', help='config file')
    parser.add_argument(
        'checkpoint',
        help='checkpoint file, or "none" for the freshly built model')
    parser.add_argument('--out', required=True, help='the .onnx file')
    parser.add_argument(
        '--verify',
        nargs='+',
        default=[],
        metavar='SAMPLE',
        help='samples to check the graph on: synthetic:SEED[:POINTS] or '
        'an info file')
    which = parser.add_mutually_exclusive_group()
    which.add_argument(
        '--sample-idx', type=int, help='sample of an info file (default 0)')
    which.add_argument('--sample-token', help='or its token')
    parser.add_argument(
        '--data-root', help="root of an info file's paths (default: its "
        'folder)')
    parser.add_argument(
        '--export-seed',
        type=int,
        default=0,
        help='seed of the synthetic sample the graph is traced with '
        '(default 0)')
    parser.add_argument(
        '--opset', type=int, default=None,
        help='ONNX opset (default 18, or 19 for a graph with deformable '
        'convolutions: ONNX DeformConv)')
    parser.add_argument(
        '--atol', type=float, default=ATOL,
        help=f'largest logit difference allowed (default {ATOL})')
    parser.add_argument(
        '--min-agreement', type=float, default=MIN_AGREEMENT,
        help='smallest share of voxels with the same argmax (default '
        f'{MIN_AGREEMENT})')
    parser.add_argument(
        '--threads', type=int, help='onnxruntime and torch threads')
    parser.add_argument(
        '--bev-output',
        action='store_true',
        help='SDG-OCC: also output the camera BEV (camera_bev) before the '
        'head, to locate a parity problem')
    parser.add_argument(
        '--latency',
        type=int,
        default=0,
        metavar='ROUNDS',
        help='also time onnxruntime against PyTorch on the CPU in this many '
        'alternating rounds, on the first --verify sample (default: 0, '
        'no timing)')
    from projects.occ_common.engine.config_checks import CfgOptionsAction
    parser.add_argument(
        '--cfg-options',
        nargs='+',
        action=CfgOptionsAction,
        help='override config settings, KEY=VALUE items')
    return parser.parse_args(argv)


def load_model(cfg, checkpoint: str) -> torch.nn.Module:
    """The config's model with the checkpoint's weights, on the CPU, in
    eval mode; checked as ``tools/test.py`` checks them.

    Raises:
        FileNotFoundError: The checkpoint does not exist.
        ValueError: Its keys or shapes differ from the model's, or it
            holds non-finite weights.
    """
    from projects.occ_common.apis import init_model
    torch.manual_seed(0)  # 'none': the same random weights every time
    return init_model(cfg, None if checkpoint == 'none' else checkpoint)


def graph_specs(model, cfg, bev_output: bool = False) -> list:
    """The model's graphs
    (:class:`~projects.occ_common.deployment.GraphSpec`), the prediction
    first.

    Raises:
        ValueError: A model this tool does not export, with the reason.
    """
    from projects.occ_common.deployment import config_time_dim
    name = type(model).__name__
    if name == 'SDGOcc':
        from projects.sdg_occ.deployment import sdg_graph_spec
        return [sdg_graph_spec(model, config_time_dim(cfg), bev_output)]
    if name == 'OccCylindrical':
        from projects.occ_cyl.deployment import occcyl_graph_specs
        return occcyl_graph_specs(model)
    raise ValueError(f'{name} has no ONNX export (docs/export.md lists '
                     'what exports)')


def load_sample(cfg, spec: str, args, tmp: str) -> dict:
    """A collated batch of one for ``synthetic:SEED[:POINTS]`` or an info
    file."""
    from projects.occ_common.deployment import (info_file_sample,
                                                synthetic_sample)
    if spec.startswith('synthetic'):
        parts = spec.split(':')
        try:
            seed = int(parts[1]) if len(parts) > 1 else 1
            points = int(parts[2]) if len(parts) > 2 else None
        except ValueError:
            raise ValueError(f'--verify {spec}: expected synthetic:SEED or '
                             'synthetic:SEED:POINTS with integers') from None
        return synthetic_sample(cfg, seed, points)
    return info_file_sample(cfg, spec, tmp, args.sample_idx,
                            args.sample_token, args.data_root)


def verify(model, spec, session, batch: dict, args) -> Dict:
    """Parity of one graph with PyTorch on one sample: the prediction's
    logits against the model's own ``_forward``, a further graph's
    outputs against its module."""
    from projects.occ_common.deployment import (logits_parity,
                                                reference_logits, run_graph)
    feeds = spec.feeds(batch)
    outputs = run_graph(session, feeds)
    if spec.part:
        with torch.no_grad():
            expected = spec.module(*feeds.values())
        result = dict(max_abs_diff=max(
            float((torch.from_numpy(outputs[name]) - value).abs().max())
            for name, value in zip(spec.output_names, expected)))
    else:
        result = logits_parity(
            reference_logits(model, batch), outputs[spec.output_names[0]])
    result['num_points'] = int(batch['inputs']['points'][0].shape[0])
    result['passed'] = (result['max_abs_diff'] <= args.atol
                        and result.get('argmax_agreement', 1.0)
                        >= args.min_agreement)
    return result


def latency(model, spec, session, batch: dict, rounds: int) -> Dict:
    """Median wall and CPU time (ms) of the graph in onnxruntime, of the
    same module in PyTorch and, for the prediction, of the model's own
    ``_forward`` (its data preprocessor and default CPU path), timed in
    alternating rounds after one untimed round."""
    from projects.occ_common.analysis.benchmarking import (alternating_runs,
                                                           round_medians)
    from projects.occ_common.deployment import reference_logits, run_graph
    feeds = spec.feeds(batch)

    def module():
        with torch.no_grad():
            spec.module(*feeds.values())

    calls = dict(onnxruntime=lambda: run_graph(session, feeds),
                 pytorch=module)
    if not spec.part:
        calls['pytorch_model'] = lambda: reference_logits(model, batch)
    medians = round_medians(alternating_runs(calls, rounds, warmup=1))
    return {
        name: dict(wall_ms=round(1e3 * value['wall_s'], 1),
                   cpu_ms=round(1e3 * value['cpu_s'], 1))
        for name, value in medians.items()
    }


def export_one(spec, feeds: dict, path: str, opset: int) -> Dict:
    """Export one graph; its summary for the JSON.

    Raises:
        ValueError: An input the graph does not read (traced as a
            constant).
    """
    from projects.occ_common.deployment import export_graph, graph_summary
    start = time.perf_counter()
    export_graph(spec.module, list(feeds.values()), path, spec.input_names,
                 spec.output_names, spec.dynamic_axes, opset)
    summary = graph_summary(path)
    if summary['unused_inputs']:
        raise ValueError(f'{path}: inputs {summary["unused_inputs"]} are '
                         'not read by the graph (traced as constants)')
    return dict(
        onnx=osp.abspath(path),
        export_s=round(time.perf_counter() - start, 2),
        opset=summary['opset'],
        nodes=summary['nodes'],
        bytes=summary['bytes'],
        ops=summary['ops'],
        inputs={
            name: dict(shape=summary['inputs'][name],
                       meaning=INPUT_DOCS.get(name, ''))
            for name in spec.input_names
        },
        outputs=summary['outputs'],
        outside_graph=spec.outside or 'nothing',
        verify={})


def main(argv=None) -> Dict:
    """Export, describe and verify; print one line per step."""
    args = parse_args(argv)
    from mmengine.config import Config
    from mmengine.registry import init_default_scope

    from projects.occ_common.deployment import onnx_session, synthetic_sample
    from projects.occ_common.engine.config_checks import apply_cfg_options
    from projects.occ_common.fileio.safe_pickle import RefusedGlobalError
    if args.threads:
        torch.set_num_threads(args.threads)
    opset = args.opset  # None: each graph's own (required_opset)
    errors = (FileNotFoundError, ValueError, RefusedGlobalError)
    try:
        if not osp.isfile(args.config):
            raise FileNotFoundError(f'config not found: {args.config}')
        cfg = Config.fromfile(args.config)
        apply_cfg_options(cfg, args)
        init_default_scope(cfg.get('default_scope', 'mmdet3d'))
        model = load_model(cfg, args.checkpoint)
        specs = graph_specs(model, cfg, args.bev_output)
    except errors as err:
        sys.exit(f'export_onnx.py: error: {err}')
    export_batch = synthetic_sample(cfg, args.export_seed)
    stem = osp.splitext(args.out)[0]
    report = dict(
        config=args.config,
        checkpoint=args.checkpoint,
        model=type(model).__name__,
        variant=getattr(model, 'variant', None),
        exported_with=f'synthetic:{args.export_seed} ('
        f'{int(export_batch["inputs"]["points"][0].shape[0])} points)',
        points_time_dim=getattr(specs[0].module, 'time_dim', None),
        graphs={})
    sessions = []
    for spec in specs:
        path = f'{stem}.{spec.part}.onnx' if spec.part else args.out
        try:
            graph = export_one(spec, spec.feeds(export_batch), path, opset)
        except errors as err:
            sys.exit(f'export_onnx.py: error: {err}')
        report['graphs'][spec.part or 'prediction'] = graph
        sessions.append(onnx_session(path, args.threads))
        print(f'exported {path}: {graph["nodes"]} nodes, '
              f'{graph["bytes"] / 2**20:.1f} MiB, opset {graph["opset"]}, '
              f'{graph["export_s"]} s')
        if spec.outside:
            print(f'outside the graph: {spec.outside}')
    failed: List[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.verify:
            try:
                batch = load_sample(cfg, name, args, tmp)
            except errors as err:
                sys.exit(f'export_onnx.py: error: {err}')
            for spec, session in zip(specs, sessions):
                result = verify(model, spec, session, batch, args)
                graph = spec.part or 'prediction'
                report['graphs'][graph]['verify'][name] = result
                agreement = ''
                if 'argmax_agreement' in result:
                    agreement = (', argmax agreement '
                                 f'{100 * result["argmax_agreement"]:.3f} %')
                which = f' ({spec.part})' if spec.part else ''
                print(f'verify {name}{which}: '
                      f'{result["num_points"]} points, max |diff| '
                      f'{result["max_abs_diff"]:.2e}{agreement}: '
                      f'{"ok" if result["passed"] else "FAILED"}')
                if not result['passed']:
                    failed.append(f'{name} ({graph})')
        if args.latency > 0:
            spec_batch = load_sample(cfg, args.verify[0], args, tmp) \
                if args.verify else export_batch
            for spec, session in zip(specs, sessions):
                timed = latency(model, spec, session, spec_batch,
                                args.latency)
                graph = spec.part or 'prediction'
                report['graphs'][graph]['latency'] = dict(
                    timed, sample=args.verify[0] if args.verify else
                    report['exported_with'], rounds=args.latency,
                    threads=torch.get_num_threads())
                print(f'latency ({graph}, median of {args.latency} '
                      'alternating rounds): ' + ', '.join(
                          f'{k} {v["wall_ms"]:.0f} ms'
                          for k, v in timed.items()))
    info = stem + '.json'
    with open(info, 'w') as file:
        json.dump(report, file, indent=1)
    print(f'info: {info}')
    if failed:
        sys.exit(f'export_onnx.py: parity failed on {", ".join(failed)}')
    return report


if __name__ == '__main__':
    main()
