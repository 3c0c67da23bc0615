"""Emulator backends. ``subproc`` (worker processes over shared memory) supports every mode."""
