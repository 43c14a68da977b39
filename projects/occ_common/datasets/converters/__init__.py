"""Converters from raw dataset layouts to this library's info files.

Imported lazily by ``tools/create_data.py`` (they need nuscenes-devkit, the
datasets themselves do not).
"""
