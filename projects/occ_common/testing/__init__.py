"""Helpers that build tiny synthetic inputs for the tests.

Import the helper modules directly (``projects.occ_common.testing.X``); this
package imports nothing eagerly so that tests pay only for what they use.
"""
