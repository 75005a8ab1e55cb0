"""nearsub: a lock-stepped, multi-process UUV simulator near a moving submarine."""

__version__ = "0.1.0"
