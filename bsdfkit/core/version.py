"""The bsdfkit version, written into the files it exports."""

__version__ = "0.1.0"
