"""Minimal stand-in for the ``ros2`` command (``run`` and ``pkg``) where ros2cli is missing."""

__version__ = '0.1.0'
