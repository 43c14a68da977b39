"""The shared helpers of the demo and the learning benchmark."""
from projects.occ_common.analysis.tool_runs import stretched_times


def test_stretched_times_scale_every_time_argument():
    """Times 2.5: a 50-iteration warm-up ends at 125, milestones [20, 23]
    become [50, 58] (57.5 rounds half to even: 58), T_max 12 becomes 30;
    type and factors are not times and are left out."""
    got = stretched_times(
        dict(type='MultiStepLR', begin=0, end=24, milestones=[20, 23],
             gamma=0.1), 2.5)
    assert got == dict(begin=0, end=60, milestones=[50, 58])
    assert stretched_times(dict(type='LinearLR', begin=0, end=50),
                           2.5) == dict(begin=0, end=125)
    assert stretched_times(dict(T_max=12), 2.5) == dict(T_max=30)


def test_a_short_run_keeps_every_scheduler_valid():
    """A 50-iteration warm-up in a run of 4 of the planned 768 iterations
    (factor 4 / 768: 0.26 iterations) keeps 1 iteration, so that mmengine
    still builds it (it refuses end <= begin); begin 10 / end 11 at a
    tenth become 1 / 2, not 1 / 1; a zero stays zero."""
    assert stretched_times(dict(begin=0, end=50), 4 / 768) == dict(begin=0,
                                                                   end=1)
    assert stretched_times(dict(begin=10, end=11), 0.1) == dict(begin=1,
                                                                end=2)
    assert stretched_times(dict(milestones=[0, 3]), 0.1) == dict(
        milestones=[0, 1])
