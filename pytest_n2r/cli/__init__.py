"""The ``n2r`` command line."""
