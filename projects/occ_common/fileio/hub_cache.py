"""Checkpoints named by URL or torchvision name, in torch hub's cache.

One download path for everything the library fetches: mmengine's
``http(s)://`` and ``torchvision://`` schemes once the restricted loader is
installed (:mod:`.checkpoint_schemes`) and the detectors' ``pretrained``
entries (:mod:`projects.occ_common.models.pretrained`). A file already in
the cache is used as is, so one copied there by hand works offline.
"""
import os
import os.path as osp
import re
from typing import Optional
from urllib.parse import urlparse

import torch

#: torchvision's ImageNet weights (``IMAGENET1K_V1``, the file mmengine's
#: ``torchvision://NAME`` resolves to), known without torchvision.
TORCHVISION_URLS = {
    'resnet18': 'https://download.pytorch.org/models/resnet18-f37072fd.pth',
    'resnet34': 'https://download.pytorch.org/models/resnet34-b627a593.pth',
    'resnet50': 'https://download.pytorch.org/models/resnet50-0676ba61.pth',
}


def torchvision_url(checkpoint: str) -> str:
    """The URL of ``torchvision://NAME`` (or ``modelzoo://NAME``).

    :data:`TORCHVISION_URLS` first; other names through mmengine's table,
    which needs torchvision.

    Args:
        checkpoint (str): ``torchvision://NAME`` or ``modelzoo://NAME``.

    Returns:
        str: The ``https://`` URL.

    Raises:
        ValueError: For a name neither table knows, listing the known ones.
    """
    name = checkpoint.split('://', 1)[1]
    if name in TORCHVISION_URLS:
        return TORCHVISION_URLS[name]
    try:
        from mmengine.runner.checkpoint import get_torchvision_models
        return get_torchvision_models()[name]
    except (ImportError, KeyError):
        raise ValueError(f'{checkpoint}: unknown torchvision model; known: '
                         f'{sorted(TORCHVISION_URLS)} (or give the path of '
                         'a downloaded file)') from None


def cached_download(url: str,
                    model_dir: Optional[str] = None,
                    name: Optional[str] = None) -> str:
    """The local file of ``url`` in torch hub's cache, downloaded once.

    Rank 0 downloads first and the other ranks wait, as mmengine does. A
    torchvision-style file name (``<name>-<sha256 prefix>.pth``) is checked
    against its hash prefix.

    Args:
        url (str): ``http(s)://`` (or ``file://``) URL.
        model_dir (str, optional): The cache folder. Defaults to
            ``torch.hub.get_dir()/checkpoints``.
        name (str, optional): What the user wrote (a ``torchvision://``
            name), for the message. Defaults to ``url``.

    Returns:
        str: Path of the downloaded (or already cached) file.

    Raises:
        RuntimeError: When the download fails, naming the URL and where to
            put the file instead.
    """
    from mmengine.dist import barrier, get_dist_info
    folder = model_dir or osp.join(torch.hub.get_dir(), 'checkpoints')
    path = osp.join(folder, osp.basename(urlparse(url).path))
    digest = re.search(r'-([0-9a-f]{8,})\.', osp.basename(path))

    def download():
        if osp.isfile(path):
            return
        os.makedirs(folder, exist_ok=True)
        try:
            torch.hub.download_url_to_file(
                url, path, hash_prefix=digest.group(1) if digest else None,
                progress=False)
        except Exception as err:  # noqa: BLE001 - re-raised with the remedy
            shown = url if name in (None, url) else f'{name} ({url})'
            raise RuntimeError(
                f'could not download {shown}: {err}. Download it elsewhere '
                f'and copy it to {path}, or give the path of a local file '
                'instead') from err

    rank, world_size = get_dist_info()
    if rank == 0:
        download()
    if world_size > 1:
        barrier()
        if rank > 0:
            download()
    return path


__all__ = ['TORCHVISION_URLS', 'cached_download', 'torchvision_url']
