"""Train a config's model for a few iterations under DDP, one process a rank.

What ``tools/train.py`` does on several GPUs, without a dataset: each rank
builds the config's model, wraps it in mmengine's
``MMDistributedDataParallel`` as the Runner does (``find_unused_parameters``
from the config, False by default), builds the config's ``optim_wrapper``
and runs ``train_step`` on a random batch of the config's shapes
(:mod:`.synthetic_batch`, a different one per rank). It reports, per rank,
the loss of each iteration, the trainable parameters that got no gradient
in the first iteration (what DDP refuses from the second on), the largest
difference of any parameter from rank 0's after the last step (zero when
the gradients were averaged across ranks) and the error, if any.

The backend follows the device: nccl with one GPU a rank, else the config's
CPU backend (gloo; :func:`..utils.cpu_dist.cpu_backend`).
``tools/analysis_tools/ddp_check.py`` is the command line.
"""
import copy
import datetime
import json
import os
import os.path as osp
import time
import traceback
from typing import Dict, List, Optional

import torch
import torch.distributed as dist

#: Seconds a collective waits for the other ranks before failing (a rank
#: that died must not hang the others).
COLLECTIVE_TIMEOUT_S = 600


def autocast_dtype(amp: Optional[str]) -> Optional[torch.dtype]:
    """``'fp16'`` / ``'bf16'`` / None as a torch dtype.

    Raises:
        ValueError: For another name.
    """
    names = {None: None, 'fp16': torch.float16, 'bf16': torch.bfloat16}
    if amp not in names:
        raise ValueError(f'amp must be one of fp16, bf16 or None, got {amp!r}')
    return names[amp]


def build_optim_wrapper_for(model: torch.nn.Module, cfg, amp: Optional[str],
                            device: torch.device):
    """The config's optimiser wrapper, with mixed precision where asked.

    On CUDA ``amp`` makes it mmengine's ``AmpOptimWrapper`` (what
    ``tools/train.py --amp`` does, dynamic loss scaling) with that dtype.
    mmengine's AmpOptimWrapper refuses the CPU: there the plain wrapper is
    kept and :func:`run_rank` wraps ``train_step`` in CPU autocast (bf16
    only, the CPU's low-precision type; no loss scale is needed for it).

    Raises:
        ValueError: fp16 on the CPU.
    """
    from mmengine.optim import build_optim_wrapper
    optim_cfg = copy.deepcopy(cfg.optim_wrapper)
    if amp is not None and device.type == 'cuda':
        optim_cfg.update(type='AmpOptimWrapper', loss_scale='dynamic',
                         dtype={'fp16': 'float16', 'bf16': 'bfloat16'}[amp])
    elif amp == 'fp16':
        raise ValueError('fp16 autocast needs CUDA (mmengine\'s '
                         'AmpOptimWrapper); use bf16 on the CPU')
    return build_optim_wrapper(model, optim_cfg)


def run_rank(rank: int, world_size: int, port: int, jobs: List[Dict],
             iters: int, device_kind: str, amp: Optional[str],
             num_points: Optional[int], timeout_s: float,
             out_dir: str) -> None:
    """One rank: for each job build, wrap, train ``iters`` steps; write
    ``out_dir/rank{rank}.json`` (a list, one result per job).

    Args:
        rank (int): This process's rank.
        world_size (int): Ranks.
        port (int): The rendezvous TCP port on localhost.
        jobs (list[dict]): Each ``config`` (file), ``options`` (overrides
            merged with ``Config.merge_from_dict``, or None) and
            ``batch_size`` (samples per rank).
        iters (int): Training iterations.
        device_kind (str): ``'cpu'`` or ``'cuda'`` (GPU ``rank``).
        amp (str, optional): ``'fp16'`` or ``'bf16'`` mixed precision.
        num_points (int, optional): Points per cloud (None: the config's
            sweeps of nuScenes size).
        timeout_s (float): Collective timeout.
        out_dir (str): Where the result goes.
    """
    from ..engine.cpu_dist import cpu_backend
    if device_kind == 'cuda':
        device = torch.device('cuda', rank)
        torch.cuda.set_device(device)
        backend = 'nccl'
    else:
        device = torch.device('cpu')
        # What a CPU run of tools/train.py takes for the configs' nccl.
        backend = cpu_backend(dict(backend='nccl'))
    os.environ.update(MASTER_ADDR='127.0.0.1', MASTER_PORT=str(port))
    dist.init_process_group(
        backend, rank=rank, world_size=world_size,
        timeout=datetime.timedelta(seconds=timeout_s))
    results = []
    for job in jobs:
        result: Dict = dict(config=job['config'], rank=rank, backend=backend,
                            losses=[], unused=[], error=None)
        try:
            _train(result, rank, device, job, iters, amp, num_points)
        except Exception as exc:  # reported, not swallowed: see ``error``
            result['error'] = f'{type(exc).__name__}: {exc}'
            result['traceback'] = traceback.format_exc()[-4000:]
        results.append(result)
        if device.type == 'cuda':
            torch.cuda.empty_cache()
    with open(osp.join(out_dir, f'rank{rank}.json'), 'w') as f:
        json.dump(results, f, indent=1)
    dist.destroy_process_group()


def _train(result: Dict, rank: int, device: torch.device, job: Dict,
           iters: int, amp: Optional[str],
           num_points: Optional[int]) -> None:
    """One job of :func:`run_rank`, filling ``result``."""
    from mmdet3d.registry import MODELS
    from mmengine.config import Config
    from mmengine.model import MMDistributedDataParallel
    from mmengine.registry import init_default_scope
    from mmengine.runner.amp import autocast

    from ..synthetic.synthetic_batch import synthetic_batch

    cfg = Config.fromfile(job['config'])
    if job.get('options'):
        cfg.merge_from_dict(job['options'])
    init_default_scope(cfg.get('default_scope', 'mmdet3d'))
    if device.type == 'cuda':
        torch.cuda.reset_peak_memory_stats(device)
    torch.manual_seed(0)  # DDP broadcasts rank 0's weights anyway
    model = MODELS.build(cfg.model).to(device)
    model.train()
    names = {p: n for n, p in model.named_parameters() if p.requires_grad}
    result['trainable'] = len(names)
    seen = set()
    hooks = [
        p.register_post_accumulate_grad_hook(
            lambda p: seen.add(names[p])) for p in names
    ]
    ddp = MMDistributedDataParallel(
        module=model,
        device_ids=[rank] if device.type == 'cuda' else None,
        broadcast_buffers=False,
        find_unused_parameters=cfg.get('find_unused_parameters', False))
    optim_wrapper = build_optim_wrapper_for(ddp, cfg, amp, device)
    batch_size = job.get('batch_size') or cfg.train_dataloader.batch_size
    batch, result['batch'] = synthetic_batch(
        cfg, batch_size, num_points, labels=True, seed=rank)
    dtype = autocast_dtype(amp)
    times: List[float] = []
    for it in range(iters):
        start = time.perf_counter()
        if dtype is not None and device.type == 'cpu':
            with autocast(device_type='cpu', dtype=dtype):
                log_vars = ddp.train_step(batch, optim_wrapper)
        else:
            log_vars = ddp.train_step(batch, optim_wrapper)
        if device.type == 'cuda':
            torch.cuda.synchronize(device)
        times.append(time.perf_counter() - start)
        loss = torch.as_tensor(log_vars['loss']).detach()
        result['losses'].append(float(loss))
        if it == 0:
            result['unused'] = sorted(set(names.values()) - seen)
            for hook in hooks:
                hook.remove()
    result['iter_s'] = times
    spread = torch.zeros((), device=device)
    for param in model.parameters():
        reference = param.detach().clone()
        dist.broadcast(reference, 0)
        spread = torch.maximum(spread,
                               (param.detach() - reference).abs().max())
    result['max_param_diff_from_rank0'] = float(spread)
    if device.type == 'cuda':
        result['peak_memory_mb'] = torch.cuda.max_memory_allocated(
            device) / 2**20


def free_port() -> int:
    """A TCP port on localhost that nothing listens on right now."""
    import socket
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def ddp_check(jobs: List[Dict],
              ranks: int = 2,
              iters: int = 2,
              device_kind: str = 'cpu',
              amp: Optional[str] = None,
              num_points: Optional[int] = None,
              timeout_s: float = COLLECTIVE_TIMEOUT_S) -> List[List[Dict]]:
    """Spawn ``ranks`` processes that run the jobs in one process group.

    Args:
        jobs (list[dict]): Each ``config`` (file), optional ``options``
            (``Config.merge_from_dict`` overrides) and ``batch_size``
            (samples per rank; the config's ``train_dataloader`` by
            default).
        ranks (int): Processes (GPUs on CUDA). Defaults to 2.
        iters (int): Training iterations. Defaults to 2 (DDP refuses unused
            parameters from the second on).
        device_kind (str): ``'cpu'`` or ``'cuda'``. Defaults to 'cpu'.
        amp (str, optional): ``'fp16'`` or ``'bf16'``.
        num_points (int, optional): Points per cloud; by default one
            nuScenes sweep's 34,720 per merged sweep of the config, as
            :func:`.synthetic_batch.synthetic_batch` makes them.
        timeout_s (float): How long a collective waits for the other
            ranks. Defaults to :data:`COLLECTIVE_TIMEOUT_S`.

    Returns:
        list[list[dict]]: Per job, one result per rank (see the module
        docstring).

    Raises:
        ValueError: More CUDA ranks than GPUs, fewer than 1 rank or
            iteration, or an unknown ``amp``.
    """
    import tempfile

    import torch.multiprocessing as mp
    if ranks < 1 or iters < 1:
        raise ValueError(f'ddp_check needs ranks >= 1 and iters >= 1, got '
                         f'{ranks} and {iters}')
    if device_kind == 'cuda' and ranks > torch.cuda.device_count():
        raise ValueError(f'ddp_check: {ranks} CUDA ranks need {ranks} GPUs, '
                         f'{torch.cuda.device_count()} visible')
    autocast_dtype(amp)
    with tempfile.TemporaryDirectory() as out_dir:
        mp.spawn(
            run_rank,
            args=(ranks, free_port(), list(jobs), iters, device_kind, amp,
                  num_points, timeout_s, out_dir),
            nprocs=ranks,
            join=True)
        per_rank = []
        for rank in range(ranks):
            with open(osp.join(out_dir, f'rank{rank}.json')) as f:
                per_rank.append(json.load(f))
    return [list(results) for results in zip(*per_rank)]
