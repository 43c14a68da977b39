"""Runtime primitives of the occupancy plugins: which code path a device
takes (:mod:`.device_path`), float32 islands under autocast
(:mod:`.precision`) and glibc's malloc settings (:mod:`.glibc_malloc`).

They import nothing else of the library; every other floor may use them.
"""
