# The toy config with the crash-test file backend of
# projects/occ_common/testing/faults.py registered; a test selects it with
# default_hooks.checkpoint.backend_args.backend=faulty_local.
_base_ = ['./toy_occ.py']

custom_imports = dict(
    imports=[
        'projects.occ_common', 'projects.occ_common.testing.toy_model',
        'projects.occ_common.testing.faults'
    ],
    allow_failed_imports=False)
