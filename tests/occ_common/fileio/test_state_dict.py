"""The one unwrapping and comparison of checkpoints
(projects/occ_common/fileio/state_dict.py)."""
import pytest
import torch

from projects.occ_common.fileio.state_dict import (compare_state_dicts,
                                                   state_dict_mismatch,
                                                   unwrap_state_dict)


def test_unwrap_every_layout():
    """A Runner checkpoint, a ``dict(model=...)`` file and a bare state
    dict give the same tensors; DDP's ``module.`` prefix goes; ``prefix``
    keeps and strips one part's keys."""
    w = torch.ones(2)
    for loaded in ({'state_dict': {'module.a.w': w}}, {'model': {'a.w': w}},
                   {'a.w': w}):
        assert unwrap_state_dict(loaded, 'f.pth') == {'a.w': w}
    assert unwrap_state_dict({'backbone.x': w, 'head.y': w}, 'f.pth',
                             'backbone.') == {'x': w}
    with pytest.raises(ValueError, match="f.pth has no key starting with "
                       "'neck.'"):
        unwrap_state_dict({'a.w': w}, 'f.pth', 'neck.')
    with pytest.raises(ValueError, match='f.pth: expected a checkpoint dict'
                       r'.*got list'):
        unwrap_state_dict([w], 'f.pth')


def test_compare_sorts_every_key_once():
    """own: a (2,), b (3,), c (1,), bn.num_batches_tracked; theirs: a (2,)
    loads, b (4,) is mis-shaped, d unexpected, e ignored; c is missing
    unless allowed; the counter is never reported."""
    own = {'a': torch.zeros(2), 'b': torch.zeros(3), 'c': torch.zeros(1),
           'bn.num_batches_tracked': torch.tensor(0)}
    theirs = {'a': torch.ones(2), 'b': torch.ones(4), 'd': torch.ones(1),
              'e': torch.ones(1)}
    load, report = compare_state_dicts(own, theirs, ignore=[r'^e$'])
    assert list(load) == ['a']
    assert report == dict(ignored=['e'], allowed_missing=[],
                          unexpected=['d'], missing=['c'],
                          shape=[('b', (4,), (3,))])
    _, report = compare_state_dicts(own, theirs, allow_missing=['^c$'])
    assert report['allowed_missing'] == ['c'] and report['missing'] == []
    assert state_dict_mismatch(own, theirs) == [
        "1 of the model's 4 tensors are missing (c)",
        "2 keys are not the model's (d, e)",
        '1 tensors have another shape (checkpoint vs model: b (4,) vs (3,))'
    ]
