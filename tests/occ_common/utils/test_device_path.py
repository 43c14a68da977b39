"""Which path a device takes, and the GPU path's chunk sizes
(projects/occ_common/utils/device_path.py)."""
import torch

from projects.occ_common.utils.device_path import (ASSUMED_FREE_BYTES,
                                                   accelerator_path,
                                                   chunk_items,
                                                   forced_accelerator_path)


def test_cpu_tensors_take_the_cpu_path_unless_forced():
    x = torch.zeros(1)
    assert not accelerator_path(x)
    with forced_accelerator_path():
        assert accelerator_path(x)
        with forced_accelerator_path(False):
            assert not accelerator_path(x)
        assert accelerator_path(x)
    assert not accelerator_path(x)


def test_chunk_items():
    """CPU: its own chunk. GPU path forced on the CPU: a quarter of the
    assumed 24 GiB at 1,024 bytes an item = 6 * 2**20 items; a paper-size
    OccCylindrical lift (6 x 50 x 58 x 100 = 1.74 M points of 64 channels
    at 16 bytes each, 1 KiB) fits in one chunk."""
    x = torch.zeros(1)
    assert chunk_items(x, 1024, 16384) == 16384
    with forced_accelerator_path():
        items = chunk_items(x, 1024, 16384)
    assert items == ASSUMED_FREE_BYTES // 4 // 1024 == 6 * 2**20
    assert items >= 6 * 50 * 58 * 100


def test_check_index_range_reads_on_the_cpu_queues_on_gpus(monkeypatch):
    """Indices 0..4 against [-1, 4): the CPU path reads the range and names
    it; the GPU path queues torch._assert_async (on a CPU tensor it fails
    at once, as a device-side assert would later), unless OCC_HOST_CHECKS=1
    asks for the host read."""
    import pytest

    from projects.occ_common.utils.device_path import check_index_range
    good, bad = torch.arange(-1, 4), torch.arange(0, 5)
    with forced_accelerator_path(False):
        check_index_range(good, -1, 4, 'rows')
        with pytest.raises(ValueError, match=r'rows must lie in \[-1, 4\), '
                           r'got values in \[0, 4\]'):
            check_index_range(bad, -1, 4, 'rows')
    with forced_accelerator_path(True):
        check_index_range(good, -1, 4, 'rows')
        with pytest.raises(RuntimeError):
            check_index_range(bad, -1, 4, 'rows')
        monkeypatch.setenv('OCC_HOST_CHECKS', '1')
        with pytest.raises(ValueError, match='rows must lie'):
            check_index_range(bad, -1, 4, 'rows')
