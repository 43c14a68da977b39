"""The library's measuring instruments, for ``tools/analysis_tools/``:
timing and peak memory, kernel-launch and host-sync counts, DDP checks,
hostile files for the fault matrix, the real nuScenes sample, and the tool
runs shared by the demo and the learning benchmark.

Import the modules directly; this package imports nothing eagerly."""
